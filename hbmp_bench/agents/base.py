"""The agent protocol and registry: agents are found by name or by ``module:Class``."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

from hbmp_bench.errors import UnknownNameError


@runtime_checkable
class Agent(Protocol):
    """A behavior policy. It sees observations and infos only, never the simulator.

    ``reset(info)`` is called with the first info of every episode; ``act(observation, info)``
    returns a behavior index in [0, 5) (speed_up, speed_down, change_left, change_right, keep).
    """

    name: str

    def reset(self, info: dict[str, Any]) -> None: ...

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> int: ...


AGENTS: dict[str, Callable[..., Agent]] = {}


def register_agent(name: str) -> Callable[[Callable[..., Agent]], Callable[..., Agent]]:
    """Class decorator adding an agent factory under ``name``."""

    def add(factory: Callable[..., Agent]) -> Callable[..., Agent]:
        if name in AGENTS:
            raise ValueError(f"agent {name!r} is already registered")
        AGENTS[name] = factory
        return factory

    return add


def load_agent(spec: str, **kwargs: Any) -> Agent:
    """An agent from a registry name (``expert``), a ``module:Class`` plug-in path, or a trained
    checkpoint file (a path ending in ``.pt``, see :mod:`hbmp_bench.agents.learned`)."""
    if spec in AGENTS:
        return AGENTS[spec](**kwargs)
    if spec.endswith(".pt"):
        from hbmp_bench.agents.learned import LearnedAgent

        return LearnedAgent(spec, **kwargs)
    if ":" in spec:
        module_name, _, attr = spec.partition(":")
        try:
            factory = getattr(importlib.import_module(module_name), attr)
        except (ImportError, AttributeError) as exc:
            raise ValueError(f"cannot load agent {spec!r}: {exc}") from exc
        agent = factory(**kwargs)
        if not isinstance(agent, Agent):
            raise TypeError(f"{spec} does not implement the Agent protocol (name, reset(info), act(observation, info))")
        return agent
    raise UnknownNameError("agent", spec, [*AGENTS, "<module:Class>", "<path/to/checkpoint.pt>"])
