"""The agent protocol and registry: agents are found by name or by ``module:Class``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

from hbmp_bench.errors import UnknownNameError, UserError
from hbmp_bench.plugins import described, resolve


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


def load_agent(spec: str, **kwargs: Any) -> Agent:
    """An agent from a registry name (``expert``), a ``module:Class`` plug-in path, or a trained
    checkpoint file (a path ending in ``.pt``, see :mod:`hbmp_bench.agents.learned`).

    Raises:
        UnknownNameError: ``spec`` is none of these.
        UserError: the plug-in's module does not import, lacks the attribute, raises while it is
            built, or builds no ``Agent`` (the plug-in's own exception is the ``__cause__``); or
            the checkpoint cannot be used (``CheckpointError``).
        FileNotFoundError: no checkpoint file at ``spec``.
    """
    if spec in AGENTS:
        return AGENTS[spec](**kwargs)
    if spec.endswith(".pt"):
        from hbmp_bench.agents.learned import LearnedAgent

        return LearnedAgent(spec, **kwargs)
    if ":" in spec:
        return _load_plugin(spec, **kwargs)
    raise UnknownNameError("agent", spec, [*AGENTS, "<module:Class>", "<path/to/checkpoint.pt>"])


def _load_plugin(spec: str, **kwargs: Any) -> Agent:
    """Build a ``module:Class`` agent; whatever the user's code raises becomes one ``UserError``."""
    factory = resolve(spec, "agent")
    attr = spec.partition(":")[2]
    try:
        agent = factory(**kwargs)
    except Exception as exc:  # noqa: BLE001 - the plug-in's constructor failed
        raise UserError(f"cannot load agent {spec!r}: {attr}() raised {described(exc)}") from exc
    if not isinstance(agent, Agent):
        raise UserError(f"cannot load agent {spec!r}: {type(agent).__name__} does not implement the Agent protocol "
                        "(name, reset(info), act(observation, info))")
    return agent

