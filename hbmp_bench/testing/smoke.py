"""Smoke run: an agent drives one short episode per task on a small town, isolated as in evaluation.

It catches what breaks a submission before a long run: an agent that cannot be built, raises in
``reset`` or ``act``, returns something that is not a behavior index in [0, 5), or takes longer
than ``max_decision_s`` for one decision (a hang included). It says nothing about driving well.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, field

from hbmp_bench.errors import ConfigError
from hbmp_bench.evaluation.pool import EpisodeOutcome, EpisodePool
from hbmp_bench.evaluation.tasks import EpisodeTask, RunnerLimits, default_fidelity
from hbmp_bench.metrics.records import AGENT_ERROR, SIM_ERROR
from hbmp_bench.scenarios import TASKS, check_task, check_town, get_suite


@dataclass(frozen=True)
class SmokeConfig:
    """What a smoke run runs.

    Attributes:
        town: a small town (``Town01``: one lane per direction, short routes).
        tasks: one episode of each.
        suite / episode: which episode of the suite's list.
        max_decisions: decisions per episode (a decision lasts 0.1 s of simulated time in event
            fidelity, until the behavior completes in continuous fidelity).
        max_decision_s: longest one ``act`` (or ``reset``) may take, pipe round trip included [s].
        agent_start_timeout_s: longest building the agent may take [s].
        fidelity: world fidelity; None is the env's default.
    """

    town: str = "Town01"
    tasks: tuple[str, ...] = field(default=TASKS)
    suite: str = "corl2017"
    episode: int = 0
    max_decisions: int = 30
    max_decision_s: float = 1.0
    agent_start_timeout_s: float = 60.0
    fidelity: str | None = None

    def __post_init__(self):
        check_town(self.town)
        for task in self.tasks:
            check_task(task)
        if not 0 <= self.episode < get_suite(self.suite).episodes_per_task:
            raise ConfigError(f"episode must be in [0, {get_suite(self.suite).episodes_per_task}), got {self.episode}")
        if self.max_decisions <= 0 or self.max_decision_s <= 0:
            raise ConfigError("max_decisions and max_decision_s must be > 0")


@dataclass(frozen=True)
class SmokeResult:
    """A passed smoke run: one outcome per task; ``max_decision_s`` is the slowest decision [s]."""

    agent: str
    outcomes: tuple[EpisodeOutcome, ...]

    @property
    def max_decision_s(self) -> float:
        return max(o.max_decision_s for o in self.outcomes)

    @property
    def decisions(self) -> int:
        return sum(o.record.decisions for o in self.outcomes)


class SmokeFailure(AssertionError):
    """The agent failed the smoke run; the message lists every failed episode and why."""


def smoke_run(agent: str, config: SmokeConfig | None = None) -> SmokeResult:
    """Run ``agent`` (registry name or ``module:Class``) for one short episode per task.

    Returns the outcomes when every episode ran its decisions (or ended) cleanly; raises
    ``SmokeFailure`` naming each failed episode with the agent's error otherwise.
    """
    config = config or SmokeConfig()
    fidelity = config.fidelity or default_fidelity()
    limits = RunnerLimits(decision_timeout_s=config.max_decision_s, agent_start_timeout_s=config.agent_start_timeout_s,
                          retries=1, max_decisions=config.max_decisions)
    tasks = [EpisodeTask(config.suite, config.town, task, config.episode, agent, fidelity) for task in config.tasks]
    with EpisodePool(1, limits) as pool:
        outcomes = tuple(pool.imap(tasks))
    failures = [o for o in outcomes if o.record.end_reason in (AGENT_ERROR, SIM_ERROR)]
    if failures:
        lines = [
            f"agent {agent!r} failed the hbmp_bench smoke run ({config.town}, episode {config.episode} of each task, "
            f"up to {config.max_decisions} decisions, {config.max_decision_s:g} s per decision allowed):"
        ]
        for o in failures:
            r = o.record
            who = "simulation error (not the agent's fault)" if r.end_reason == SIM_ERROR else "agent error"
            lines.append(f"- {r.town}/{r.task}/{r.episode}, {who} after {r.decisions} decisions:")
            lines.append(textwrap.indent(r.error.strip() or "(no message)", "    "))
        raise SmokeFailure("\n".join(lines))
    return SmokeResult(agent, outcomes)
