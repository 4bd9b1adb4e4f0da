"""How far policies' choices differ from one driver's, state by state (``hbmp-bench agreement``).

One agent drives the episodes (greedily, as evaluated); at every decision each other agent is asked
what it would do in the same state, and the pairs that differ are counted with the situation they
arose in: the signal of the light ahead when its stop line is within :data:`LIGHT_NEAR_M` (``r``, ``y``,
``g``/``G``), with ``standing`` below :data:`STANDING_MPS`, else ``no light near``. It tells how far RL
fine-tuning moved a policy from its imitation start, and where (a PPO run that changed 46 % of il's
choices mostly swapped equivalent ones, keep and speed_down while standing at a red).

The agents run in this process (trusted checkpoints and registry names; no sandbox), on one env built
with the options every one of them asks for.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass, field
from typing import Any

from hbmp_bench.errors import UserError

LIGHT_NEAR_M = 40.0
"""A light's signal is the situation of a decision when its stop line is this close [m]."""
STANDING_MPS = 0.5
"""Below this speed [m/s] the ego counts as standing."""


@dataclass
class Agreement:
    """What one other agent would have done in the driver's states.

    Attributes:
        agent: its spec.
        decisions: states compared.
        differ: states where its choice differs from the driver's.
        pairs: (driver's choice, its choice, situation) -> count, for the differing states.
    """

    agent: str
    decisions: int = 0
    differ: int = 0
    pairs: collections.Counter = field(default_factory=collections.Counter)

    @property
    def differ_pct(self) -> float:
        return 100.0 * self.differ / self.decisions if self.decisions else 0.0

    def to_dict(self, top: int = 10) -> dict[str, Any]:
        return {"agent": self.agent, "decisions": self.decisions, "differ": self.differ,
                "differ_pct": round(self.differ_pct, 2),
                "pairs": [{"driver": a, "other": b, "situation": s, "count": n}
                          for (a, b, s), n in self.pairs.most_common(top)]}


def situation(info: dict[str, Any]) -> str:
    """The situation of a decision from the env's non-privileged scene fields."""
    scene = info.get("scene", {})
    light, distance = scene.get("light", ""), scene.get("stop_distance_m", float("inf"))
    if not light or distance > LIGHT_NEAR_M:
        return "no light near"
    standing = " standing" if scene.get("speed_mps", 0.0) < STANDING_MPS else ""
    return f"light {light}{standing}"


def _action_name(action: Any) -> str:
    """A behavior's name (``planning.BEHAVIORS``), or a control vector as text."""
    from hbmp_bench.planning.behaviors import BEHAVIORS

    return BEHAVIORS[action] if isinstance(action, int) and 0 <= action < len(BEHAVIORS) else str(action)


def merged_env_kwargs(agents: dict[str, Any]) -> dict[str, Any]:
    """The env options every agent asks for; raises ValueError naming the agents whose options conflict."""
    from hbmp_bench.agents import agent_env_kwargs

    merged: dict[str, Any] = {}
    owner: dict[str, str] = {}
    for name, agent in agents.items():
        for key, value in agent_env_kwargs(agent).items():
            if key == "privileged":  # the privileged scene only adds to info: anyone may have it
                merged[key] = merged.get(key, False) or bool(value)
            elif key in merged and merged[key] != value:
                raise UserError(f"{owner[key]} and {name} need different observations ({key}: {merged[key]!r} vs "
                                 f"{value!r}): compare agents trained on the same observation")
            else:
                merged[key], owner[key] = value, name
    return merged


def agreement(driver: str, others: list[str], suite: str, town: str, task: str, episodes: int,
              fidelity: str | None = None, progress: bool = True) -> list[Agreement]:
    """Drive the first ``episodes`` episodes of (``suite``, ``town``, ``task``) with ``driver`` and compare
    every other agent's choice in each of its states. Returns one :class:`Agreement` per other agent."""
    from tqdm import tqdm

    from hbmp_bench.agents import load_agent
    from hbmp_bench.envs.behavior_env import BehaviorEnv
    from hbmp_bench.rollout import EpisodeHooks, run_episode

    if not others:
        raise UserError("give at least one agent to compare with the driver (--with)")
    if episodes < 1:
        raise UserError(f"episodes must be >= 1, got {episodes}")
    agents = {spec: load_agent(spec) for spec in dict.fromkeys([driver, *others])}
    options = {} if fidelity is None else {"fidelity": fidelity}
    env = BehaviorEnv(town=town, task=task, suite=suite, **options, **merged_env_kwargs(agents))
    results = [Agreement(spec) for spec in others]
    states: list[tuple[Any, dict, Any]] = []  # (observation, info, the driver's action) of the episode
    last: list[tuple[Any, dict]] = []  # the observation the driver acts on next

    def on_reset(obs, info):
        last[:] = [(obs, info)]

    def on_step(obs, reward, terminated, truncated, info):
        if not (terminated or truncated):
            last[:] = [(obs, info)]

    def check_action(action, decisions):
        states.append((last[0][0], last[0][1], action))
        return action

    try:
        count = min(episodes, len(env.episodes))
        for index in tqdm(range(count), desc="agreement", unit="ep", disable=not progress):
            states.clear()
            run_episode(env, agents[driver], seed=index, options={"episode_index": index},
                        hooks=EpisodeHooks(on_reset=on_reset, on_step=on_step, check_action=check_action))
            for result in results:
                other = agents[result.agent]
                other.reset(states[0][1] if states else {})
                for obs, info, chosen in states:
                    theirs = other.act(obs, info)
                    result.decisions += 1
                    if theirs != chosen:
                        result.differ += 1
                        result.pairs[(_action_name(chosen), _action_name(theirs), situation(info))] += 1
    finally:
        env.close()
    return results
