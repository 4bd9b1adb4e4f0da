"""The flat end-to-end baseline's environment: continuous control without a behavior layer.

The paper's baseline "directly maps input to u without hierarchical modeling": the agent sets the
ego's acceleration and steering every 0.1 s. Same scenarios, traffic, detectors and pictures as
:class:`~hbmp_bench.envs.BehaviorEnv`: the same parallel env with the ego's driver configured as
:class:`~hbmp_bench.envs.drivers.ControlDriver` (``ego_driver="control"``).

## Action space
``Box(-1, 1, (2,), float32)``: ``[a, s]``: ``a > 0`` throttle (fraction of the bicycle model's
``max_accel``), ``a < 0`` brake (fraction of ``max_decel``); ``s`` steering (fraction of
``max_steer``, positive = left). One action lasts one 0.1 s simulation step (10 Hz).

## Observation space
``occupancy`` M_t as the behavior env; ``road`` (12,): R_t (10 entries, see
:mod:`hbmp_bench.envs.observation`) then the ego's lateral error to the followed lane divided by
the lane width and its heading error divided by π/2, both clipped to [-2, 2].

## Rewards
``reward="dense"``: r_T + r_t with r_t = λ(dt·(c_dist + c_obs)) of the ego's state after the step
(:func:`hbmp_bench.planning.instant_costs`), the paper's baseline reward without the velocity term;
``dt`` = 0.1 s keeps Σr_t on HBMP's per-second scale (one r_k per ~1 s behavior).
``reward="sparse"``: r_T only.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from hbmp_bench.envs.observation import LANE_WIDTH_M, ROAD_FEATURES
from hbmp_bench.envs.traffic_v0 import TrafficParallelEnv
from hbmp_bench.envs.world import EGO_ID
from hbmp_bench.planning.behaviors import Behavior


class ControlEnv(gym.Env):
    """Acceleration and steering at 10 Hz on the behavior env's scenarios (see the module docstring).

    Arguments as :class:`~hbmp_bench.envs.BehaviorEnv`; ``fidelity`` must be None or ``continuous``
    (the ego always runs the bicycle model).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, town: str = "Town01", task: str = "Navigation", suite: str = "corl2017",
                 episode_index: int | None = None, random_goals: bool = False, fidelity: str | None = None,
                 reward: str = "dense", observation: str = "deformed", observation_config=None,
                 road_profile: str = "paper", density: str | None = None, render_mode: str | None = None, privileged: bool = False):
        if fidelity not in (None, "continuous"):
            raise ValueError(f"the control env always runs the bicycle model; fidelity must be 'continuous', got {fidelity!r}")
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode {render_mode!r} is not supported; valid: None, 'rgb_array'")
        self.parallel = TrafficParallelEnv(
            town=town, task=task, suite=suite, episode_index=episode_index, random_goals=random_goals,
            density=density, controlled="none", ego_fidelity="continuous", ego_driver="control", reward=reward,
            observation=observation, observation_config=observation_config, road_profile=road_profile,
            render_mode=render_mode, privileged=privileged)
        self.render_mode = render_mode
        self.action_space = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.observation_space = spaces.Dict(
            occupancy=self.parallel.observation_space(EGO_ID)["occupancy"],
            road=spaces.Box(-2.0, 2.0, (self.parallel.observation_space(EGO_ID)["road"].shape[0] + 2,),
                            dtype=np.float32),
        )

    @property
    def world(self):
        """The driving world (:class:`~hbmp_bench.envs.world.DrivingWorld`)."""
        return self.parallel.world

    @property
    def episodes(self):
        return self.parallel.episodes

    def record(self, agent: str = ""):
        """The episode record so far (None before the first reset)."""
        return self.parallel.record(agent)

    def _extend(self, obs: dict) -> dict:
        e, th = self.world.ego_driver.errors()
        extra = np.clip([e / LANE_WIDTH_M, th / (np.pi / 2)], -2.0, 2.0).astype(np.float32)
        return {"occupancy": obs["occupancy"], "road": np.concatenate([obs["road"].astype(np.float32), extra])}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        obs, infos = self.parallel.reset(seed=seed, options=options)
        driver, ego = self.world.ego_driver, self.world.ego
        driver.path = driver.lane_path(ego.followed_lane, ego.next_edges(), ego.next_lanes())
        return self._extend(obs[EGO_ID]), self._without_behaviors(infos[EGO_ID])

    def step(self, action):
        if EGO_ID not in self.parallel.agents:
            raise RuntimeError("call reset() before step() (and again after an episode ends)")
        action = np.asarray(action, dtype=np.float32).reshape(-1)
        if action.shape != (2,) or not np.all(np.isfinite(action)):
            raise ValueError(f"action must be 2 finite numbers [accel, steer] in [-1, 1], got {action!r}")
        self.world.ego_driver.set_control(action)
        obs, rewards, terms, truncs, infos = self.parallel.step({EGO_ID: int(Behavior.KEEP)})
        info = self._without_behaviors(infos[EGO_ID])
        info["control"] = action.tolist()
        return self._extend(obs[EGO_ID]), rewards[EGO_ID], terms[EGO_ID], truncs[EGO_ID], info

    @staticmethod
    def _without_behaviors(info: dict) -> dict:
        """``info`` without the behavior layer's keys: this env has no behaviors to choose or mask (a reset's
        info kept ``action_mask`` once, and a training batch mixing a reset and a step could not be stacked)."""
        for key in ("behavior", "behavior_executed", "action_mask"):
            info.pop(key, None)
        return info

    def render(self):
        return self.parallel.render()

    def drain_frames(self) -> list[np.ndarray]:
        return self.parallel.drain_frames()

    def close(self):
        self.parallel.close()
