"""Single-ego gymnasium environment: the behavior layer of HBMP on a SUMO town."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from hbmp_bench.envs.config import WorldConfig
from hbmp_bench.envs.observation import ObservationConfig
from hbmp_bench.envs.traffic_v0 import TrafficParallelEnv
from hbmp_bench.envs.world import EGO_ID
from hbmp_bench.planning.behaviors import BEHAVIORS


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
    ``reward="dense"`` (default, HBMP): r_k + r_T. r_k = λ(c̃_total) = −scale · c̃_total
    (``ExecutorConfig.reward_scale``, 0.25), c̃_total the mean cost of
    the planner's chosen trajectories over the behavior (0 in event fidelity); r_T is the paper's
    terminal reward, paid when the event happens: +100 goal, −50 collision or timeout, −10 red
    light, −1 wrong lane / off-road, and −50 more when the episode ends before the goal otherwise
    than by a collision or a timeout (left the network; a violation under the paper's protocol: see
    ``metrics.episode.TERMINAL_REWARD``). ``reward="sparse"`` (HBMP-S): r_T only.
    ``info["reward_components"]`` has both; ``info["planner_costs"]`` the cost terms.

    ## Episode end
    Terminated at the goal (ego centre within the suite's radius, 2 m), when the ego leaves the
    network, and, when the suite says so, at a collision (NoCrash) or any violation (the paper's
    protocol). Truncated at the suite's timeout (CoRL2017: route length at 10 km/h + 10 s and a full red at
    every light on the route).
    ``info["episode"]`` then holds the episode record.

    ## Arguments
    town, task: which scenario (``Town01``..``Town05`` or an imported map; ``Straight``, ``OneTurn``,
        ``Navigation``, ``NavigationDynamic``).
    suite: episode list and rules (``corl2017`` default, ``hbmp``, ``nocrash-*``).
    episode_index: fix one episode of the list; None cycles by reset seed (seed % episodes).
    random_goals: ignore the suite list and draw a fresh start and goal every reset (training).
    fidelity, reward, decision_period_s: see :class:`WorldConfig` (None: its defaults).
    observation: ``deformed`` or ``vehicle_centric`` M_t; grid options via ``observation_config``.
    road_profile: R_t's entries: ``paper`` (the paper's ten) or ``metric`` (and the stop distance
        and speed in metric units; see :mod:`hbmp_bench.envs.observation`).
    density: override background traffic (``empty``, ``corl``, ``regular``, ``dense``); another
        value raises ValueError here.
    privileged: add the privileged fields to ``info["scene"]`` (the rule-based expert's; see
        :class:`WorldConfig`); default off.

    ## Implementation
    The parallel env (:class:`~hbmp_bench.envs.traffic_v0.TrafficParallelEnv`) with no background
    agent, seen from the ego: one implementation for both.

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
        road_profile: str = "paper",
        density: str | None = None,
        render_mode: str | None = None,
        privileged: bool = False,
    ):
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode {render_mode!r} is not supported; valid: None, 'rgb_array'")
        self.parallel = TrafficParallelEnv(
            town=town, task=task, suite=suite, episode_index=episode_index, random_goals=random_goals,
            density=density, controlled="none", ego_fidelity=WorldConfig.fidelity if fidelity is None else fidelity,
            reward=reward, decision_period_s=decision_period_s, observation=observation,
            observation_config=observation_config, road_profile=road_profile, render_mode=render_mode,
            privileged=privileged)
        self.action_space = self.parallel.action_space(EGO_ID)
        self.observation_space = self.parallel.observation_space(EGO_ID)
        self.render_mode = render_mode

    @property
    def scenario(self):
        """The scenario (:class:`~hbmp_bench.envs.config.ScenarioConfig`)."""
        return self.parallel.scenario

    @property
    def config(self) -> WorldConfig:
        return self.parallel.config

    @property
    def town(self) -> str:
        return self.scenario.town

    @property
    def task(self) -> str:
        return self.scenario.task

    @property
    def episodes(self):
        return self.scenario.episodes

    @property
    def traffic(self):
        """The background traffic ``density`` sets for every episode (None: each episode's own)."""
        return self.scenario.traffic

    @property
    def world(self):
        """The driving world (:class:`~hbmp_bench.envs.world.DrivingWorld`)."""
        return self.parallel.world

    def record(self, agent: str = ""):
        """The episode record so far (None before the first reset)."""
        return self.parallel.record(agent)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        obs, infos = self.parallel.reset(seed=seed, options=options)
        return obs[EGO_ID], infos[EGO_ID]

    def step(self, action):
        if EGO_ID not in self.parallel.agents:
            raise RuntimeError("call reset() before step() (and again after an episode ends)")
        if isinstance(action, (bool, np.bool_)) or not (
                self.action_space.contains(action) or isinstance(action, (int, np.integer)) and 0 <= int(action) < 5):
            raise ValueError(f"action must be an int in [0, {len(BEHAVIORS)}) ({', '.join(BEHAVIORS)}), "
                             f"got {type(action).__name__} {action!r}")
        obs, rewards, terms, truncs, infos = self.parallel.step({EGO_ID: int(action)})
        return obs[EGO_ID], rewards[EGO_ID], terms[EGO_ID], truncs[EGO_ID], infos[EGO_ID]

    def render(self) -> np.ndarray | None:
        """``rgb_array``: the top-down view now, (H, W, 3) uint8 (see :mod:`hbmp_bench.render`)."""
        return self.parallel.render()

    def drain_frames(self) -> list[np.ndarray]:
        """All frames rendered at every 0.1 s simulation step since the last call (the frames
        between decisions), oldest first; empty unless ``render_mode="rgb_array"``."""
        return self.parallel.drain_frames()

    def close(self):
        self.parallel.close()
