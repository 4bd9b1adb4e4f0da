"""Agents: the protocol, the registry, the built-in agents (expert, random, keep) and the learned
ones (il, hbmp, hbmp-s, flat; torch loads only when one is made)."""

from hbmp_bench.agents import expert, learned, simple  # noqa: F401  (registration)
from hbmp_bench.agents.base import AGENTS, PRIVILEGED_OPTION, Agent, agent_env_kwargs, register_agent
from hbmp_bench.agents.loading import load_agent

__all__ = ["AGENTS", "PRIVILEGED_OPTION", "Agent", "agent_env_kwargs", "load_agent", "register_agent"]
