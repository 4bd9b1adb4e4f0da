"""Single-ego gymnasium environment: the behavior layer of HBMP on a SUMO town."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from hbmp_bench.envs.observation import ObservationConfig, observation_space
from hbmp_bench.envs.world import BEHAVIORS, DrivingWorld, WorldConfig
from hbmp_bench.scenarios import TASKS, check_task, check_town, get_suite, sample_episode, suite_episodes, traffic_for


class BehaviorEnv(gym.Env):
    """HBMP behavior environment.

    ## Description
    The ego drives from a start to a goal pose along a global route on a SUMO recreation of a
    CARLA town, among background vehicles and pedestrians driven by SUMO. Each step the agent
    picks one of five behaviors; the behavior is executed until it completes: by default
    (``fidelity="continuous"``) the paper's behavior-conditioned sampling motion planner replans
    at 10 Hz and drives a bicycle model until the ego has converged to the target lane and speed
    (1-8 s, ``info["duration_s"]``); with ``fidelity="event"`` SUMO's speed and lane-change
    commands complete it within one 0.1 s decision (the paper's SUMO stage).

    ## Action space
    ``Discrete(5)``, the paper's order: 0 speed_up, 1 speed_down, 2 change_left, 3 change_right,
    4 keep. A behavior infeasible for R_t (no lane on that side) is executed as keep;
    ``info["action_mask"]`` marks the feasible ones. An action outside 0..4, or a bool, raises ValueError.

    ## Observation space
    ``Dict(occupancy=Box(0, 1, (1, rows, cols), float32), road=Box(0, 2, (10,), float32))``:
    M_t and R_t, see :mod:`hbmp_bench.envs.observation` for every cell and entry.

    ## Rewards
    ``reward="dense"`` (default, HBMP): r_k + r_T. r_k = λ(c̃_total) = −c̃_total, the mean cost of
    the planner's chosen trajectories over the behavior (0 in event fidelity); r_T is the paper's
    terminal reward, paid when the event happens: +100 goal, −50 collision or timeout, −10 red
    light, −1 wrong lane / off-road. ``reward="sparse"`` (HBMP-S): r_T only.
    ``info["reward_components"]`` has both; ``info["planner_costs"]`` the cost terms.

    ## Episode end
    Terminated at the goal (ego centre within the suite's radius, 2 m), when the ego leaves the
    network, and, when the suite says so, at a collision (NoCrash) or any violation (the paper's
    protocol). Truncated at the suite's timeout (route length at 10 km/h + 10 s for CoRL2017).
    ``info["episode"]`` then holds the episode record.

    ## Arguments
    town, task: which scenario (``Town01``..``Town05`` or an imported map; ``Straight``, ``OneTurn``,
        ``Navigation``, ``NavigationDynamic``).
    suite: episode list and rules (``corl2017`` default, ``hbmp``, ``nocrash-*``).
    episode_index: fix one episode of the list; None cycles by reset seed (seed % episodes).
    random_goals: ignore the suite list and draw a fresh start and goal every reset (training).
    fidelity, reward, decision_period_s: see :class:`WorldConfig` (None: its defaults).
    observation: ``deformed`` or ``vehicle_centric`` M_t; grid options via ``observation_config``.
    density: override background traffic (``empty``, ``corl``, ``regular``, ``dense``); another
        value raises ValueError here.

    ## Version history
    v0: first release.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        town: str = "Town01",
        task: str = "Navigation",
        suite: str = "corl2017",
        episode_index: int | None = None,
        random_goals: bool = False,
        fidelity: str | None = None,
        reward: str = "dense",
        decision_period_s: float = 0.1,
        observation: str = "deformed",
        observation_config: ObservationConfig | None = None,
        density: str | None = None,
        render_mode: str | None = None,
    ):
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode {render_mode!r} is not supported; valid: None, 'rgb_array'")
        self.town = check_town(town)
        self.task = check_task(task)
        self.suite = get_suite(suite)
        self.random_goals = random_goals
        self.density = density
        self.traffic = None if density is None else traffic_for(self.town, self.task, density)
        """The background traffic ``density`` sets for every episode (None: each episode's own);
        an unknown density fails here, before any simulation starts."""
        obs_cfg = observation_config or ObservationConfig(kind=observation)
        fidelity = WorldConfig.fidelity if fidelity is None else fidelity
        self.config = WorldConfig(fidelity=fidelity, reward=reward, decision_period_s=decision_period_s,
                                  observation=obs_cfg)
        self.episodes = () if random_goals else suite_episodes(self.suite.name, town, task)
        if episode_index is not None and not 0 <= episode_index < len(self.episodes):
            raise ValueError(f"episode_index must be in [0, {len(self.episodes)}), got {episode_index}")
        self.episode_index = episode_index
        self.action_space = spaces.Discrete(len(BEHAVIORS))
        self.observation_space = observation_space(obs_cfg)
        self.render_mode = render_mode
        self._renderer = None
        self._frames: list[np.ndarray] = []
        self._last_behavior = ""
        self._world: DrivingWorld | None = None
        self._running = False

    @property
    def world(self) -> DrivingWorld:
        if self._world is None:
            self._world = DrivingWorld(self.town, self.config)
            if self.render_mode == "rgb_array":
                self._world.on_substep = self._capture
        return self._world

    # ------------------------------------------------------------- pictures
    def _frame(self) -> np.ndarray:
        if self._renderer is None:
            from hbmp_bench.render import TopDownRenderer

            self._renderer = TopDownRenderer(self.world.net)
        w = self.world
        caption = f"{w.town} {self.task}  t={w.sim.time:5.1f} s  {w._ego.speed:4.1f} m/s  {self._last_behavior}"
        return self._renderer.frame(w.scene_view(caption))

    def _capture(self) -> None:
        self._frames.append(self._frame())

    def render(self) -> np.ndarray | None:
        """``rgb_array``: the top-down view now, (H, W, 3) uint8 (see :mod:`hbmp_bench.render`)."""
        if self.render_mode is None:
            return None
        if not self._running and self._world is None:
            raise RuntimeError("call reset() before render()")
        return self._frames[-1] if self._frames else self._frame()

    def drain_frames(self) -> list[np.ndarray]:
        """All frames rendered at every 0.1 s simulation step since the last call (the frames
        between decisions), oldest first; empty unless ``render_mode="rgb_array"``."""
        frames, self._frames = self._frames, []
        return frames

    def _pick_episode(self, options: dict | None):
        opts = options or {}
        if self.random_goals:
            traffic = self.traffic if self.traffic is not None else traffic_for(self.town, self.task, None)
            seed = int(self.np_random.integers(2**31))
            return sample_episode(self.town, "Navigation" if self.task == "NavigationDynamic" else self.task,
                                  np.random.default_rng(seed), suite=self.suite, index=0, seed=seed, traffic=traffic)
        index = opts.get("episode_index", self.episode_index)
        if index is None:
            index = int(self.np_random.integers(len(self.episodes)))
        episode = self.episodes[index]
        if self.traffic is not None:
            import dataclasses

            episode = dataclasses.replace(episode, traffic=self.traffic)
        return episode

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        episode = self._pick_episode(options)
        obs, info = self.world.start(episode, seed=int(self.np_random.integers(2**31)))
        self._running = True
        self._frames, self._last_behavior = [], ""
        if self.render_mode == "rgb_array":
            self._capture()
        return obs, info

    def step(self, action):
        if not self._running:
            raise RuntimeError("call reset() before step() (and again after an episode ends)")
        if isinstance(action, (bool, np.bool_)) or not (
                self.action_space.contains(action) or isinstance(action, (int, np.integer)) and 0 <= int(action) < 5):
            raise ValueError(f"action must be an int in [0, {len(BEHAVIORS)}) ({', '.join(BEHAVIORS)}), "
                             f"got {type(action).__name__} {action!r}")
        self._last_behavior = BEHAVIORS[int(action)]
        obs, reward, terminated, truncated, info = self.world.step(int(action))
        if terminated or truncated:
            self._running = False
        return obs, reward, terminated, truncated, info

    def close(self):
        if self._world is not None:
            self._world.close()
        self._running = False
