"""Gymnasium env: an hbmp_bench agent drives a highway-env vehicle through the sharable representation."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from hbmp_bench import __version__
from hbmp_bench.envs.observation import ObservationConfig, observation_space
from hbmp_bench.envs.registration import RECORD_KEY
from hbmp_bench.errors import ConfigError
from hbmp_bench.metrics.detectors import EVENT_KINDS
from hbmp_bench.metrics.episode import EpisodeId, EpisodeScorer, terminal_reward
from hbmp_bench.metrics.records import EpisodeRecord
from hbmp_bench.planning.behaviors import BEHAVIORS, Behavior
from hbmp_bench.plugins import resolve
from hbmp_bench.transfer.adapter import HighwayAdapter, to_meta_action
from hbmp_bench.transfer.scenes import TransferScene, get_scene

SUITE = "highway-transfer"
"""Suite name of the records these episodes produce."""


@dataclass(frozen=True)
class TransferConfig:
    """Options of the highway-env transfer env.

    Attributes:
        observation: M_t grid (``kind`` deformed or vehicle_centric).
        decision_period_s: simulated time per decision [s] (0.1: the SUMO env's period); one
            highway-env policy step, and one simulation step.
        speed_step_mps: spacing of the ego's target-speed grid [m/s] (FASTER / SLOWER move one
            grid step from the current speed).
        lane_change_max_s: a lane change runs until the ego settles in the target lane or this
            long [s] (the paper's behavior-completion rule; highway-env needs ~2 s per change).
        settle_lateral_m / settle_heading_rad: the ego has settled when its lateral offset from
            the target lane's centre and its heading error are below these.
    """

    observation: ObservationConfig = field(default_factory=ObservationConfig)
    decision_period_s: float = 0.1
    speed_step_mps: float = 2.0
    lane_change_max_s: float = 5.0
    settle_lateral_m: float = 0.5
    settle_heading_rad: float = 0.1

    def __post_init__(self):
        hz = 1.0 / self.decision_period_s if self.decision_period_s > 0 else 0.0
        if not self.decision_period_s > 0 or abs(hz - round(hz)) > 1e-6:
            raise ConfigError(f"decision_period_s must be 1/n s for a whole n (0.1, 0.2, 0.5, 1.0), got {self.decision_period_s!r}")
        if not self.speed_step_mps > 0 or not self.lane_change_max_s > 0:
            raise ConfigError("speed_step_mps and lane_change_max_s must be > 0")
        if not self.settle_lateral_m > 0 or not self.settle_heading_rad > 0:
            raise ConfigError("settle_lateral_m and settle_heading_rad must be > 0")

    @property
    def decision_hz(self) -> int:
        return int(round(1.0 / self.decision_period_s))


def _no_events() -> dict[str, int]:
    """Event counts by kind: the SUMO kinds (``EVENT_KINDS``) plus ``collision_other`` (obstacles)."""
    return {k: 0 for k in (*EVENT_KINDS, "collision_other")}


def _vehicle_classes() -> tuple[type, ...]:
    """highway-env's traffic model ``IDMVehicle`` and all its subclasses."""
    from highway_env.vehicle.behavior import IDMVehicle

    def subclasses(cls):
        return (cls, *(s for sub in cls.__subclasses__() for s in subclasses(sub)))

    return tuple(dict.fromkeys(subclasses(IDMVehicle)))


_VEHICLE_CLASS_PARAMS = ("DISTANCE_WANTED", "COMFORT_ACC_MAX", "COMFORT_ACC_MIN", "TIME_WANTED", "DELTA")


def _own_params(cls: type) -> dict[str, Any]:
    return {name: cls.__dict__[name] for name in _VEHICLE_CLASS_PARAMS if name in cls.__dict__}


_VEHICLE_CLASS_DEFAULTS: dict[type, dict[str, Any]] = {cls: _own_params(cls) for cls in _vehicle_classes()}
"""highway-env's traffic-model parameters as the library defines them (taken when this module loads)."""


def _restore_vehicle_class_defaults() -> None:
    """Undo highway-env's process-wide changes to its traffic models before every episode.

    highway-env's intersection scene sets ``DISTANCE_WANTED``, ``COMFORT_ACC_MAX`` and
    ``COMFORT_ACC_MIN`` on its traffic class (highway_env/envs/intersection_env.py), so every
    scene run later in the same process had more aggressive traffic: the same seed gave another
    episode depending on what ran before. The intersection scene sets its values again when it
    builds its vehicles.
    """
    for cls in _vehicle_classes():
        own = _VEHICLE_CLASS_DEFAULTS.setdefault(cls, _own_params(cls))
        for name in _VEHICLE_CLASS_PARAMS:
            if name in own:
                setattr(cls, name, own[name])
            elif name in cls.__dict__:  # set on a subclass by a scene: inherit again
                delattr(cls, name)


class HighwayTransferEnv(gym.Env):
    """HBMP behavior layer on a highway-env scene (zero-shot transfer from SUMO).

    ## Description
    The same contract as :class:`hbmp_bench.envs.BehaviorEnv` (spaces, action order, ``info`` keys),
    on a highway-env scene instead of a SUMO town: M_t and R_t are built from highway-env's road
    network (see :mod:`hbmp_bench.transfer.adapter`), and the five behaviors are executed as
    highway-env DiscreteMetaActions (speed_up -> FASTER, speed_down -> SLOWER, change_left ->
    LANE_LEFT, change_right -> LANE_RIGHT, keep -> IDLE). Background traffic is highway-env's
    (IDM + MOBIL).

    ## Action space
    ``Discrete(5)``: 0 speed_up, 1 speed_down, 2 change_left, 3 change_right, 4 keep. A behavior
    infeasible for R_t is executed as keep (``info["action_mask"]``). A decision lasts
    ``decision_period_s``; a lane change lasts until the ego has settled in the target lane (at
    most ``lane_change_max_s``).

    ## Observation space
    ``Dict(occupancy=Box(0, 1, (1, rows, cols), float32), road=Box(0, 2, (10,), float32))``.

    ## Rewards
    The paper's r_T as in the SUMO env: +100 success, -50 collision or timeout, -1 off-road entry.

    ## Episode end
    Terminated on a collision (``vehicle.crashed``) or success: highway = no collision for the
    scene's duration (then truncated=False, terminated=True), merge / roundabout / intersection =
    reaching the scene's goal road (see :mod:`hbmp_bench.transfer.scenes`). Truncated at the
    duration otherwise (timeout). Off-road (``not vehicle.on_road``) is counted, not terminal.
    ``info["hbmp_record"]`` then holds the episode record (suite ``highway-transfer``, town and task =
    scene, fidelity ``highway-env:<observation kind>``).

    ## Seeding
    ``reset(seed=k)`` fixes highway-env's scene and traffic; the record's episode index is k (or
    ``options["episode_index"]``). Same seed, same agent -> identical episode record.

    ## Arguments
    scene: ``highway``, ``merge``, ``roundabout`` or ``intersection``.
    observation: ``deformed`` or ``vehicle_centric``; grid options via ``observation_config``.
    decision_period_s, speed_step_mps, lane_change_max_s: see :class:`TransferConfig`.
    render_mode: None or ``rgb_array`` (highway-env's renderer).

    ## Version history
    v0: first release.
    """

    metadata = {"render_modes": ["rgb_array"]}

    def __init__(self, scene: str = "highway", observation: str = "deformed",
                 observation_config: ObservationConfig | None = None, road_profile: str = "paper", decision_period_s: float = 0.1,
                 speed_step_mps: float = 2.0, lane_change_max_s: float = 5.0, render_mode: str | None = None):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode {render_mode!r} is not supported; valid: None, 'rgb_array'")
        self.scene: TransferScene = get_scene(scene)
        obs_cfg = observation_config or ObservationConfig(kind=observation, road=road_profile)
        self.config = TransferConfig(observation=obs_cfg, decision_period_s=decision_period_s,
                                     speed_step_mps=speed_step_mps, lane_change_max_s=lane_change_max_s)
        self.render_mode = render_mode
        self.action_space = spaces.Discrete(len(BEHAVIORS))
        self.observation_space = observation_space(obs_cfg)
        self._hw = None
        self._running = False
        self._episode_index = -1

    # ------------------------------------------------------------ lifecycle
    @property
    def highway_env(self):
        """The wrapped highway-env environment (created on first use)."""
        if self._hw is None:
            cls = resolve(self.scene.env_class, "highway-env class")
            config = self.scene.highway_config(self.config.decision_hz, self.config.speed_step_mps)
            self._hw = cls(config=config, render_mode=self.render_mode)
        return self._hw

    @property
    def ego(self):
        return self.highway_env.vehicle

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        _restore_vehicle_class_defaults()
        hw_seed = int(self.np_random.integers(2**31))
        self.highway_env.reset(seed=hw_seed)
        opts = options or {}
        default_index = int(seed) if seed is not None else self._episode_index + 1
        self._episode_index = int(opts.get("episode_index", default_index))
        self._seed = int(seed) if seed is not None else hw_seed
        self.adapter = HighwayAdapter(self.highway_env.road, self.scene, self.config.observation)
        ego = self.ego
        self._steps = 0
        self._decisions = 0
        self._totals = _no_events()
        self._crashed = bool(ego.crashed)
        self._on_road = bool(ego.on_road)
        self._done_reason = ""
        self._init_progress(ego)
        self._running = True
        return self._observe(_no_events())

    def close(self):
        if self._hw is not None:
            self._hw.close()
        self._running = False

    def render(self):
        if self.render_mode is None:
            return None
        return self.highway_env.render()

    # ----------------------------------------------------------- progress
    def _init_progress(self, ego) -> None:
        """Offsets [m] of the roads on the nominal route from the start to the goal road."""
        self._offsets: dict[tuple[str, str], float] = {}
        self.route_length_m = 0.0
        goal = self.scene.goal_road
        if goal is None:
            self.score = EpisodeScorer(0.0, np.array(ego.position, dtype=float))
            return
        index = ego.lane_index
        s0 = float(self.adapter.network.get_lane(index).local_coordinates(ego.position)[0])
        total, route = -s0, getattr(ego, "route", None)
        for _ in range(64):
            self._offsets.setdefault(index[:2], total)
            if index[:2] == tuple(goal):
                break
            total += float(self.adapter.network.get_lane(index).length)
            index = self.adapter.next_lane(index, route)
            if index is None:
                break
        self.route_length_m = max(self._offsets.get(tuple(goal), 0.0) + self.scene.goal_s_m, 0.0)
        self.score = EpisodeScorer(self.route_length_m, np.array(ego.position, dtype=float))

    def _update_progress(self, ego) -> None:
        offset = self._offsets.get(tuple(ego.lane_index[:2]))
        if offset is None or self.route_length_m <= 0:
            return
        self.score.progressed_to(offset + float(ego.lane.local_coordinates(ego.position)[0]))

    @property
    def route_completion(self) -> float:
        """Fraction of the route driven; for a survive scene, of the duration survived."""
        if self._done_reason in ("goal", "survived"):
            return 1.0
        if self.scene.goal_road is None:
            return float(np.clip(self.time_s / self.scene.duration_s, 0.0, 1.0))
        return self.score.completion(False)

    @property
    def time_s(self) -> float:
        return self._steps * self.config.decision_period_s

    # ----------------------------------------------------------------- step
    def step(self, action):
        if not self._running:
            raise RuntimeError("call reset() before step() (and again after an episode ends)")
        is_int = isinstance(action, (int, np.integer)) or (
            isinstance(action, np.ndarray) and action.shape == () and np.issubdtype(action.dtype, np.integer))
        if not is_int or not 0 <= int(action) < len(BEHAVIORS):
            raise ValueError(f"action must be an int in [0, {len(BEHAVIORS)}) ({', '.join(BEHAVIORS)}), got {action!r}")
        behavior = int(action)
        executed = behavior if self._mask[behavior] else Behavior.KEEP
        events = _no_events()
        start = self.time_s
        target_before = self.ego.target_lane_index
        self._advance(to_meta_action(executed), events)
        if executed in (Behavior.CHANGE_LEFT, Behavior.CHANGE_RIGHT) and self.ego.target_lane_index != target_before:
            idle = to_meta_action(Behavior.KEEP)
            while not self._done_reason and not self._settled() and self.time_s - start < self.config.lane_change_max_s - 1e-9:
                self._advance(idle, events)
        self._decisions += 1
        obs, info = self._observe(events)
        info["behavior"] = BEHAVIORS[behavior]
        info["behavior_executed"] = BEHAVIORS[executed]
        info["duration_s"] = self.time_s - start
        reward = self._terminal_reward(events)
        info["reward_components"] = {"r_k": 0.0, "r_T": reward}
        terminated = self._done_reason in ("goal", "survived", "collision")
        truncated = self._done_reason == "timeout"
        if terminated or truncated:
            self._running = False
            info[RECORD_KEY] = self.record().to_dict()
        return obs, reward, terminated, truncated, info

    def _settled(self) -> bool:
        ego = self.ego
        if tuple(ego.lane_index) != tuple(ego.target_lane_index):
            return False
        s, lateral = ego.lane.local_coordinates(ego.position)
        heading_error = (ego.heading - ego.lane.heading_at(s) + np.pi) % (2 * np.pi) - np.pi
        return abs(lateral) < self.config.settle_lateral_m and abs(heading_error) < self.config.settle_heading_rad

    def _advance(self, meta_action: int, events: dict[str, int]) -> None:
        """One highway-env step (``decision_period_s``) and the detectors."""
        self.highway_env.step(meta_action)
        self._steps += 1
        ego = self.ego
        self.score.moved_to(np.array(ego.position, dtype=float))
        self._update_progress(ego)
        if ego.crashed and not self._crashed:
            self._crashed = True
            kind = "collision_other" if self._hit_obstacle(ego) else "collision_vehicle"
            self._totals[kind] += 1
            events[kind] += 1
        on_road = bool(ego.on_road)
        if self._on_road and not on_road:
            self._totals["off_road"] += 1
            events["off_road"] += 1
        self._on_road = on_road
        if self._crashed:
            self._done_reason = "collision"
        elif self._reached_goal(ego):
            self._done_reason = "goal" if self.scene.goal_road is not None else "survived"
        elif self.time_s >= self.scene.duration_s - 1e-9:
            self._done_reason = "timeout"

    def _reached_goal(self, ego) -> bool:
        goal = self.scene.goal_road
        if goal is None:
            return self.time_s >= self.scene.duration_s - 1e-9
        if tuple(ego.lane_index[:2]) != tuple(goal):
            return False
        return float(ego.lane.local_coordinates(ego.position)[0]) >= self.scene.goal_s_m

    def _hit_obstacle(self, ego) -> bool:
        """Whether the nearest other crashed object is a static obstacle rather than a vehicle."""
        crashed = [o for o in (*self.highway_env.road.vehicles, *self.highway_env.road.objects)
                   if o is not ego and getattr(o, "crashed", False)]
        if not crashed:
            return False
        nearest = min(crashed, key=lambda o: float(np.hypot(*(np.asarray(o.position) - ego.position))))
        return nearest not in self.highway_env.road.vehicles

    def _terminal_reward(self, events: dict[str, int]) -> float:
        return terminal_reward(goal=self._done_reason in ("goal", "survived"),
                               collisions=events["collision_vehicle"] + events["collision_other"],
                               timed_out=self._done_reason == "timeout", off_road=events["off_road"])

    # -------------------------------------------------------------- observe
    def _observe(self, events: dict[str, int]) -> tuple[dict, dict]:
        obs, scene, mask = self.adapter.observe(self.ego)
        self._mask = mask
        info = {
            "action_mask": mask,
            "events": {k: int(events[k]) for k in EVENT_KINDS},
            "infractions": dict(self._totals),
            "time_s": self.time_s,
            "route_completion": self.route_completion,
            "episode_key": f"{SUITE}/{self.scene.name}/{self._episode_index}",
            "scene": scene,
        }
        return obs, info

    def record(self, agent: str = "") -> EpisodeRecord:
        """The episode record so far (final once the episode has ended)."""
        episode = EpisodeId(SUITE, self.scene.name, self.scene.name, self._episode_index, self._seed,
                            f"highway-env:{self.config.observation.kind}", round(self.route_length_m, 2))
        return self.score.record(episode, agent=agent, package_version=__version__, totals=dict(self._totals),
                                 success=self._done_reason in ("goal", "survived"), end_reason=self._done_reason,
                                 duration_s=self.time_s, decisions=self._decisions, completion=self.route_completion)
