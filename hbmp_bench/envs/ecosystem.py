"""Wrappers that take the parallel env to the ecosystem's generic multi-agent trainers.

The env keeps PettingZoo's conventions (a Dict observation, agents leave ``env.agents`` when their
episode ends, an agent still executing its behavior gets ``decision_required=False`` and its action
is ignored). Generic trainers want other things; each wrapper here does one of them and is
documented in ``docs/recipes.md``:

- :class:`FlatObservations`: a ``Box`` observation, ``concat(M_t.ravel(), R_t)`` (SuperSuit's
  ``black_death`` and vector envs, RLlib's default encoders take only Box observations).
- :class:`BlackDeath`: every possible agent in every step, an ended one with zero observation and
  reward 0, until the episode ends for all (SuperSuit's ``pettingzoo_env_to_vec_env_v1``; SuperSuit's
  own ``black_death_v3`` ends an episode only when every agent is both terminated *and* truncated,
  which never happens here: the ego terminates at its goal and the others are truncated).
- :class:`DecisionsOnly`: RLlib's multi-agent dict convention: an agent is in the observation dict
  only when it has a decision to make (or its episode ends), and its rewards since its last
  observation are summed into that step, so no learner sees a transition whose action was ignored.

Train SB3 through SuperSuit with every agent in event fidelity (``fidelity="event"``,
``background_fidelity="event"``): then every live agent decides at every step, and a vector env's
slot never records an ignored action. RLlib takes any fidelity through :class:`DecisionsOnly`
(:func:`hbmp_bench.envs.rllib.rllib_env` applies it).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo.utils.wrappers import BaseParallelWrapper


def flat_space(space: spaces.Dict) -> spaces.Box:
    """The Box of ``concat(occupancy.ravel(), road)`` for the env's Dict observation space."""
    parts = [space[key] for key in ("occupancy", "road")]
    low = np.concatenate([p.low.ravel() for p in parts]).astype(np.float32)
    high = np.concatenate([p.high.ravel() for p in parts]).astype(np.float32)
    return spaces.Box(low, high, dtype=np.float32)


def flatten_observation(obs: dict) -> np.ndarray:
    """(rows·cols + len(R_t),) float32: M_t row-major, then R_t."""
    return np.concatenate([np.asarray(obs["occupancy"], dtype=np.float32).ravel(),
                           np.asarray(obs["road"], dtype=np.float32).ravel()])


class FlatObservations(BaseParallelWrapper):
    """The parallel env with ``Box`` observations (see the module docstring); everything else as is."""

    def __init__(self, env):
        super().__init__(env)
        self._spaces = {a: flat_space(env.observation_space(a)) for a in env.possible_agents}

    def observation_space(self, agent: str) -> spaces.Box:
        return self._spaces[agent]

    def reset(self, seed: int | None = None, options: dict | None = None):
        obs, infos = self.env.reset(seed=seed, options=options)
        return {a: flatten_observation(o) for a, o in obs.items()}, infos

    def step(self, actions: dict[str, Any]):
        obs, rewards, terms, truncs, infos = self.env.step(actions)
        return {a: flatten_observation(o) for a, o in obs.items()}, rewards, terms, truncs, infos


class BlackDeath(BaseParallelWrapper):
    """Every possible agent in every step until the episode ends for all (see the module docstring).

    An agent whose episode ended gets a zero observation, reward 0, ``terminated = truncated = False``
    and ``info = {}`` until the last live agent ends; that step reports every agent's end (an ended
    agent as the way it ended), so a vector env resets all its slots together. Needs Box
    observations (:class:`FlatObservations`).
    """

    def __init__(self, env):
        super().__init__(env)
        for agent in env.possible_agents:
            if not isinstance(env.observation_space(agent), spaces.Box):
                raise TypeError(f"BlackDeath needs Box observations (wrap with FlatObservations first), "
                                f"{agent} has {env.observation_space(agent)}")
        self._ended: dict[str, tuple[bool, bool]] = {}

    def reset(self, seed: int | None = None, options: dict | None = None):
        obs, infos = self.env.reset(seed=seed, options=options)
        self.agents = list(self.env.possible_agents)
        self._ended = {}
        return obs, infos

    def step(self, actions: dict[str, Any]):
        live = set(self.env.agents)
        obs, rewards, terms, truncs, infos = self.env.step({a: v for a, v in actions.items() if a in live})
        for agent in obs:
            if terms[agent] or truncs[agent]:
                self._ended[agent] = (bool(terms[agent]), bool(truncs[agent]))
        over = not self.env.agents
        out = ({}, {}, {}, {}, {})
        for agent in self.possible_agents:
            if agent in obs:
                out[0][agent], out[1][agent], out[4][agent] = obs[agent], rewards[agent], infos[agent]
            else:
                out[0][agent] = np.zeros_like(self.observation_space(agent).low)
                out[1][agent], out[4][agent] = 0.0, {}
            term, trunc = self._ended.get(agent, (False, False))
            out[2][agent], out[3][agent] = (term, trunc) if over else (False, False)
        if over:
            self.agents = []
        return out


class DecisionsOnly(BaseParallelWrapper):
    """RLlib's multi-agent dict convention (see the module docstring).

    ``step`` returns observations and infos only for the agents with ``decision_required`` or whose
    episode ended in this step; each such agent's reward is the sum of its rewards since it was
    last observed. ``terminations`` / ``truncations`` name the agents that ended in this step.
    Actions are expected for the agents of the last observation dict (others' are ignored).
    """

    def reset(self, seed: int | None = None, options: dict | None = None):
        obs, infos = self.env.reset(seed=seed, options=options)
        self._pending = {a: 0.0 for a in self.env.agents}
        return obs, infos

    def step(self, actions: dict[str, Any]):
        obs, rewards, terms, truncs, infos = self.env.step(actions)
        out = ({}, {}, {}, {}, {})
        for agent in obs:
            self._pending[agent] = self._pending.get(agent, 0.0) + float(rewards[agent])
            ended = bool(terms[agent] or truncs[agent])
            if ended or infos[agent].get("decision_required"):
                out[0][agent], out[4][agent] = obs[agent], infos[agent]
                out[1][agent] = self._pending.pop(agent)
                if not ended:
                    self._pending[agent] = 0.0
            if ended:
                out[2][agent], out[3][agent] = bool(terms[agent]), bool(truncs[agent])
        return out
