"""Run agents on episodes and collect records.

``run_job`` runs a job in this process (the agent shares the process with the simulation: for
debugging and trusted agents). ``run_jobs`` runs jobs through the isolated ``EpisodePool``. Both
make each agent's env as it asks for (``tasks.with_agent_env``), e.g. the expert's
``privileged=True`` or the flat baseline's control env.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from hbmp_bench.metrics.records import EpisodeRecord

if TYPE_CHECKING:
    from hbmp_bench.evaluation.tasks import RunnerLimits


@dataclass(frozen=True)
class Job:
    """Episodes of one (suite, town, task) for one agent; ``fidelity`` None is the env's default."""

    suite: str
    town: str
    task: str
    agent: str
    episodes: tuple[int, ...]
    fidelity: str | None = None


def run_job(job: Job) -> tuple[list[EpisodeRecord], float, int]:
    """Run a job's episodes in this process, in the env the agent asks for; returns (records,
    wall seconds, decisions)."""
    from hbmp_bench.agents import load_agent
    from hbmp_bench.evaluation.channel import AgentDescription
    from hbmp_bench.evaluation.env_process import build_env
    from hbmp_bench.evaluation.tasks import EpisodeTask, RunnerLimits, default_fidelity, with_agent_env
    from hbmp_bench.rollout import AgentFailed, EnvFailed, run_episode

    agent = load_agent(job.agent)
    wanted = with_agent_env(RunnerLimits(), AgentDescription.of(agent))
    first = EpisodeTask(job.suite, job.town, job.task, 0, job.agent, job.fidelity or default_fidelity())
    env = build_env(first, wanted.env_factory, dict(wanted.env_kwargs))
    records, decisions = [], 0
    start = time.perf_counter()
    try:
        for index in job.episodes:
            try:
                run = run_episode(env, agent, seed=index, options={"episode_index": index})
            except (AgentFailed, EnvFailed) as exc:  # in-process debugging: the original error
                raise exc.__cause__ from None
            decisions += run.decisions
            records.append(dataclasses.replace(EpisodeRecord(**run.record(env)), agent=job.agent))
    finally:
        env.close()
    return records, time.perf_counter() - start, decisions


def run_jobs(jobs: Iterable[Job], workers: int = 1, progress: bool = True,
             limits: RunnerLimits | None = None) -> list[EpisodeRecord]:
    """Run jobs' episodes in ``workers`` isolated slots (agent and simulation in their own processes,
    each agent in the env it asks for, isolated as ``limits`` say: default ``RunnerLimits()``); records
    come back ordered like the jobs. A failing agent gives ``agent_error`` records."""
    from hbmp_bench.evaluation.evaluate import iter_outcomes
    from hbmp_bench.evaluation.tasks import EpisodeTask, default_fidelity

    jobs = list(jobs)
    fidelity = default_fidelity()
    tasks = [EpisodeTask(j.suite, j.town, j.task, i, j.agent, j.fidelity or fidelity) for j in jobs for i in j.episodes]
    records = [r for o in iter_outcomes(tasks, workers=workers, limits=limits, progress=progress) for r in o.records]
    order = {t.key: k for k, t in enumerate(tasks)}
    return sorted(records, key=lambda r: order.get(r.key, len(order)))
