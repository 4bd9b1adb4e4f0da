"""Loading an agent: from a registry name, a ``module:Class`` plug-in or a trained checkpoint file.

Above the protocol and registry (:mod:`hbmp_bench.agents.base`) and the learned agents
(:mod:`hbmp_bench.agents.learned`, imported only when a checkpoint file is asked for).
"""

from __future__ import annotations

from typing import Any

from hbmp_bench.agents.base import AGENTS, Agent
from hbmp_bench.errors import UnknownNameError, UserError
from hbmp_bench.plugins import described, resolve


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

