"""The parallel env as an RLlib ``MultiAgentEnv`` (needs the ``rllib`` extra).

``rllib_env(config)`` is RLlib's own ``ParallelPettingZooEnv`` over
``DecisionsOnly(FlatObservations(parallel_env(**config)))``
(:mod:`hbmp_bench.envs.ecosystem`), with the two things RLlib's wrapper gets wrong for this env:

- ``__all__``: RLlib's wrapper sets ``terminateds["__all__"] = all(terminateds.values())``; when the
  last goal-directed agent reaches its goal it is terminated and the circulating ones are truncated, so
  neither ``all`` holds and RLlib would step a finished episode. Here the episode is over when no agent
  is left: ``terminateds["__all__"]`` when a goal-directed agent (``ego``, ``ego1`` ...) was terminated
  at that step, else ``truncateds["__all__"]``.
- ``render()``: RLlib's wrapper calls ``par_env.render(mode)``; PettingZoo's ``render()`` takes no
  argument.

Register it with ``ray.tune.registry.register_env("hbmp_traffic", rllib_env)``; ``config`` is the
keyword form of :class:`~hbmp_bench.envs.traffic_v0.TrafficParallelEnv` (an ``EnvContext`` is a
dict). Observations are Box, so RLlib's default encoders apply; every agent's spaces are the
same, so one shared policy fits (``policy_mapping_fn=lambda agent_id, *a, **k: "shared"``).
"""

from __future__ import annotations

from typing import Any

from hbmp_bench.envs.ecosystem import DecisionsOnly, FlatObservations


def rllib_env(config: dict[str, Any] | None = None):
    """The RLlib ``MultiAgentEnv`` of ``parallel_env(**config)`` (see the module docstring).

    Raises:
        ImportError: RLlib is not installed (``pip install "hbmp-bench[rllib]"``).
    """
    try:
        from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise ImportError('rllib_env needs RLlib: pip install "hbmp-bench[rllib]"') from exc
    from hbmp_bench.envs.traffic_v0 import TrafficParallelEnv

    class HbmpMultiAgentEnv(ParallelPettingZooEnv):
        """RLlib's wrapper with this env's ``__all__`` and ``render`` (see the module docstring)."""

        def step(self, action_dict):
            obs, rewards, terms, truncs, infos = self.par_env.step(action_dict)
            over = not self.par_env.agents
            goal_terminated = any(terms.get(a) for a in self.par_env.unwrapped.goal_agents)
            terms["__all__"] = over and goal_terminated
            truncs["__all__"] = over and not goal_terminated
            return obs, rewards, terms, truncs, infos

        def render(self):
            return self.par_env.render()

    return HbmpMultiAgentEnv(DecisionsOnly(FlatObservations(TrafficParallelEnv(**dict(config or {})))))
