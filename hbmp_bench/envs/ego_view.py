"""The one base of the package's single-ego gymnasium envs: the ego's view of a
:class:`~hbmp_bench.envs.traffic_v0.TrafficParallelEnv`.

A view owns no simulation logic: its spaces are the parallel env's for the ego, ``reset`` and
``step`` return the ego's entries, and an action is validated once, at the parallel env's door
(:meth:`~hbmp_bench.envs.traffic_v0.TrafficParallelEnv.check_actions`); rendering, episode length
(``max_cycles``), copies and the record key (``info["hbmp_record"]``) are the parallel env's, see
:mod:`hbmp_bench.envs.traffic_v0`. The views differ only in
how the parallel env is configured (:class:`~hbmp_bench.envs.BehaviorEnv`: no background agent;
:class:`~hbmp_bench.envs.control_env.ControlEnv`: the ego's control driver) and, for
:class:`~hbmp_bench.envs.traffic_v0.EgoEnv`, in who acts for the background agents.
"""

from __future__ import annotations

import inspect
from typing import Any

import gymnasium as gym
import numpy as np

from hbmp_bench.envs.config import env_configs
from hbmp_bench.envs.world import EGO_ID
from hbmp_bench.errors import ConfigError


def keyword_signature(cls: type, *leading: inspect.Parameter) -> inspect.Signature:
    """The signature a view shows (``help``, ``inspect``): ``leading`` keyword-only parameters, then
    ``scenario``, ``world``, ``render_mode``, ``max_cycles`` and the keyword form of :func:`env_configs`."""
    kw = inspect.Parameter.KEYWORD_ONLY
    own = [inspect.Parameter(name, kw, default=None) for name in ("scenario", "world", "render_mode", "max_cycles")]
    options = list(inspect.signature(env_configs).parameters.values())
    return inspect.Signature([*leading, *own, *options])


class EgoView(gym.Env):
    """The ego's view of a parallel env (see the module docstring).

    Args:
        parallel: the parallel env the view shows; the view closes it.
    """

    metadata = {"render_modes": ["rgb_array", "rgb_array_list"], "render_fps": 10}

    def __init__(self, parallel):
        if len(parallel.goal_agents) > 1:
            raise ConfigError(f"{parallel.scenario.suite} episodes have {len(parallel.goal_agents)} goal-directed "
                              "vehicles and a single-ego env drives one: use traffic_v0.parallel_env (one agent each) "
                              "or hbmp_bench.envs.scene_env.SceneEnv (all in one call)")
        self.parallel = parallel
        self.render_mode = parallel.render_mode
        self.action_space = parallel.action_space(EGO_ID)
        self.observation_space = parallel.observation_space(EGO_ID)

    # ------------------------------------------------------------ the configs
    @property
    def scenario(self):
        """The scenario (:class:`~hbmp_bench.envs.config.ScenarioConfig`)."""
        return self.parallel.scenario

    @property
    def config(self):
        """The world options (:class:`~hbmp_bench.envs.config.WorldConfig`)."""
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

    # ------------------------------------------------------------ the episode
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        obs, infos = self.parallel.reset(seed=seed, options=options)
        self._after_reset(obs, infos)
        return obs[EGO_ID], infos[EGO_ID]

    def _after_reset(self, obs: dict, infos: dict) -> None:
        """What a view does once the parallel env has reset (nothing here)."""

    def step(self, action):
        if EGO_ID not in self.parallel.agents:
            raise RuntimeError("call reset() before step() (and again after an episode ends)")
        obs, rewards, terms, truncs, infos = self.parallel.step({EGO_ID: action})
        return obs[EGO_ID], rewards[EGO_ID], terms[EGO_ID], truncs[EGO_ID], infos[EGO_ID]

    def render(self) -> np.ndarray | list[np.ndarray] | None:
        """``rgb_array``: the top-down view now, (H, W, 3) uint8 (see :mod:`hbmp_bench.render`);
        ``rgb_array_list``: the frames of every SUMO step since the last call."""
        return self.parallel.render()

    def drain_frames(self) -> list[np.ndarray]:
        """All frames rendered at every 0.1 s simulation step since the last call (the frames
        between decisions), oldest first; empty unless ``render_mode="rgb_array_list"``."""
        return self.parallel.drain_frames()

    def close(self):
        self.parallel.close()
