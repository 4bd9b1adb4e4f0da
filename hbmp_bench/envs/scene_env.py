"""A multi-agent episode as one episode for runners: every goal-directed vehicle of the scene decides
through one call.

Usage::

    from hbmp_bench.envs.scene_env import SceneEnv
    from hbmp_bench.agents.scene import SceneAgent
    env = SceneEnv(town="Town03", suite="multi")             # 8 goal-directed vehicles, SUMO's traffic
    agent = SceneAgent("il")                                  # one policy drives them all
    observations, info = env.reset(seed=0, options={"episode_index": 0})
    agent.reset(info)
    while True:
        actions = agent.act(observations, info)               # {vehicle: action} in one call
        observations, reward, terminated, truncated, info = env.step(actions)
        if terminated or truncated:
            break
    records = info["hbmp_record"]                             # one record dict per vehicle, ``ego`` first

This is what the evaluation runs for a multi-agent suite (``Suite.agents`` > 1): the loop of
:func:`hbmp_bench.rollout.run_episode`, unchanged, with dicts where a single-ego env has one value.

## Spaces
``observations``: {vehicle: observation} of the vehicles that decide now (``info["decision_required"]``
in the parallel env), each in :attr:`vehicle_observation_space`; ``actions``: {vehicle: action} for
exactly those vehicles, each in :attr:`vehicle_action_space` (a behavior, or a control vector with
``ego_driver="control"``). Vehicles are ``ego``, ``ego1`` ... (:attr:`vehicles`).

## Steps and ends
``step`` steps the parallel env (:class:`~hbmp_bench.envs.traffic_v0.TrafficParallelEnv`, no circulating
background agents) until a vehicle needs a decision or the scene ends: when every vehicle's episode has
ended (each by its suite's rules: goal, violation, its own timeout). ``terminated`` is True then;
``truncated`` instead when ``max_cycles`` cut it. ``reward`` is the sum of the vehicles' rewards since
the last call (a scene has no reward of its own; a trainer uses the parallel env).

## Infos
``info["vehicles"]``: {vehicle: info} of the deciding vehicles (the parallel env's per-vehicle info);
``info["ended"]``: {vehicle: record dict} of the vehicles whose episode ended since the last call; at
the scene's end ``info["hbmp_record"]``: every vehicle's record dict, ``ego`` first.
"""

from __future__ import annotations

from typing import Any

from hbmp_bench.envs.registration import RECORD_KEY
from hbmp_bench.envs.traffic_v0 import TrafficParallelEnv
from hbmp_bench.metrics.records import DECISION_CAP


class SceneEnv:
    """Every goal-directed vehicle of an episode as one episode (see the module docstring).

    Args: as :class:`~hbmp_bench.envs.traffic_v0.TrafficParallelEnv` (``scenario=`` / ``world=`` or the
    keyword form, ``render_mode``, ``max_cycles``), without circulating agents (``controlled="none"``).
    """

    metadata = TrafficParallelEnv.metadata

    def __init__(self, **kwargs: Any):
        if "controlled" in kwargs:
            raise TypeError("a scene has no circulating agents: controlled is not an option of SceneEnv")
        self.parallel = TrafficParallelEnv(controlled="none", **kwargs)
        self.vehicles: list[str] = list(self.parallel.goal_agents)
        self.render_mode = self.parallel.render_mode
        self._records: dict[str, dict] = {}

    @property
    def unwrapped(self) -> "SceneEnv":
        return self

    @property
    def vehicle_observation_space(self):
        return self.parallel.observation_space(self.vehicles[0])

    @property
    def vehicle_action_space(self):
        return self.parallel.action_space(self.vehicles[0])

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start a scene (``options``: ``episode_index``, ``salt``, as the parallel env's)."""
        obs, infos = self.parallel.reset(seed=seed, options=options)
        self._records = {}
        return self._deciding(obs, infos, {})

    def step(self, actions: dict[str, Any]):
        """Act for the deciding vehicles; returns (observations, reward, terminated, truncated, info)."""
        if not self.parallel.agents:
            raise RuntimeError("call reset() before step() (and again after the scene ends)")
        latest_obs, latest_infos, ended, reward = {}, {}, {}, 0.0
        while True:
            obs, rewards, _, _, infos = self.parallel.step(actions)
            reward += float(sum(rewards.values()))
            latest_obs.update(obs)
            latest_infos.update(infos)
            for vehicle, info in infos.items():
                if RECORD_KEY in info:
                    ended[vehicle] = self._records[vehicle] = info[RECORD_KEY]
            live = self.parallel.agents
            if not live or any(latest_infos[v]["decision_required"] for v in live):
                break
            actions = {}
        observations, info = self._deciding({v: latest_obs[v] for v in live}, latest_infos, ended)
        over = not live
        if over:
            info[RECORD_KEY] = [self._records[v] for v in self.vehicles]
        capped = over and any(r["end_reason"] == DECISION_CAP for r in self._records.values())
        return observations, reward, over and not capped, capped, info

    def _deciding(self, obs: dict, infos: dict, ended: dict) -> tuple[dict, dict]:
        deciding = [v for v in self.parallel.agents if infos[v]["decision_required"]]
        return {v: obs[v] for v in deciding}, {"vehicles": {v: infos[v] for v in deciding}, "ended": ended}

    def records(self, agent: str = "") -> list:
        """Every vehicle's :class:`~hbmp_bench.metrics.EpisodeRecord` so far (final for those that ended)."""
        return self.parallel.records(agent)

    def record(self, agent: str = ""):
        """The ``ego``'s record so far (:meth:`records` has every vehicle's)."""
        return self.parallel.record(agent)

    def render(self):
        return self.parallel.render()

    def close(self) -> None:
        self.parallel.close()
