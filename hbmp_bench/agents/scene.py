"""One policy for every goal-directed vehicle of a scene (:class:`~hbmp_bench.envs.scene_env.SceneEnv`).

``SceneAgent(spec)`` turns an agent (:func:`~hbmp_bench.agents.loading.load_agent`'s ``spec``: a name,
``module:Class`` or a checkpoint) into one that takes the scene's {vehicle: observation} and returns
{vehicle: action} in one call:

- an agent with ``act_batch(observations, infos) -> actions`` (dicts keyed by vehicle; the learned
  agents have one: one forward pass for every deciding vehicle) is built once and gets every decision
  of the scene in one call; it is reset with each vehicle's first info and keeps any state per vehicle;
- any other agent is built once per vehicle (its state, e.g. the expert's, is its vehicle's), reset
  with that vehicle's first info, and asked per vehicle.
"""

from __future__ import annotations

from typing import Any

from hbmp_bench.agents.base import agent_env_kwargs
from hbmp_bench.agents.loading import load_agent


class SceneAgent:
    """See the module docstring.

    Args:
        spec: the agent (:func:`~hbmp_bench.agents.loading.load_agent`).
        **kwargs: passed to every ``load_agent`` call.

    Attributes:
        name / env_kwargs / env_factory / fingerprint: the wrapped agent's (what the evaluation reads).
        batched: the wrapped agent has ``act_batch``.
    """

    def __init__(self, spec: str, **kwargs: Any):
        self.spec, self._kwargs = spec, kwargs
        self.prototype = load_agent(spec, **kwargs)
        self.name = self.prototype.name
        self.env_kwargs = agent_env_kwargs(self.prototype)
        for attribute in ("env_factory", "fingerprint"):
            if hasattr(self.prototype, attribute):
                setattr(self, attribute, getattr(self.prototype, attribute))
        self.batched = callable(getattr(self.prototype, "act_batch", None))
        self._agents: dict[str, Any] = {}

    def reset(self, info: dict[str, Any]) -> None:
        """A new scene: ``info["vehicles"]`` holds the first info of every vehicle."""
        self._agents = {}
        self._meet(info)

    def _meet(self, info: dict[str, Any]) -> None:
        for vehicle, vehicle_info in info["vehicles"].items():
            if vehicle not in self._agents:
                agent = self.prototype if self.batched else (
                    self.prototype if not self._agents else load_agent(self.spec, **self._kwargs))
                agent.reset(vehicle_info)
                self._agents[vehicle] = agent

    def act(self, observations: dict[str, Any], info: dict[str, Any]) -> dict[str, Any]:
        """{vehicle: action} for every vehicle in ``observations``."""
        self._meet(info)
        infos = info["vehicles"]
        if self.batched:
            return self.prototype.act_batch(observations, {v: infos[v] for v in observations})
        return {v: self._agents[v].act(observations[v], infos[v]) for v in observations}
