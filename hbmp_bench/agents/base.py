"""The agent protocol and registry (:func:`~hbmp_bench.agents.loading.load_agent` finds agents by name, by
``module:Class`` or by checkpoint file)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable



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

PRIVILEGED_OPTION = "privileged"
"""The env option an agent sets to True in its ``env_kwargs`` to read the privileged fields of
``info["scene"]`` (``WorldConfig.privileged``); an evaluation that grants it is marked privileged."""


def agent_env_kwargs(agent: Any) -> dict[str, Any]:
    """The env options ``agent`` asks for: its optional ``env_kwargs`` attribute (the observation
    kind a policy was trained on; ``privileged: True`` for the rule-based expert). Every runner
    builds the agent's env with them (the isolated evaluation through ``with_agent_env``)."""
    return dict(getattr(agent, "env_kwargs", None) or {})


def register_agent(name: str) -> Callable[[Callable[..., Agent]], Callable[..., Agent]]:
    """Class decorator adding an agent factory under ``name``."""

    def add(factory: Callable[..., Agent]) -> Callable[..., Agent]:
        if name in AGENTS:
            raise ValueError(f"agent {name!r} is already registered")
        AGENTS[name] = factory
        return factory

    return add
