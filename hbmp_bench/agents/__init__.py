"""Agents: the protocol, the registry and the built-in agents (expert, random, keep)."""

from hbmp_bench.agents import expert, simple  # noqa: F401  (registration)
from hbmp_bench.agents.base import AGENTS, Agent, load_agent, register_agent

__all__ = ["AGENTS", "Agent", "load_agent", "register_agent"]
