"""Run agents on episodes and collect records.

``run_job`` runs a job in this process (the agent shares the process with the simulation: for
debugging and trusted agents). ``run_jobs`` runs jobs through the isolated ``EpisodePool``. Both
make each agent's env with the options it asks for (``agents.base.agent_env_kwargs``; in the
pool through ``evaluate.with_agent_env``), e.g. the expert's ``privileged=True``.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterable
from dataclasses import dataclass

from hbmp_bench.metrics.records import EpisodeRecord


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
    """Run a job's episodes in this process; returns (records, wall seconds, decisions)."""
    from hbmp_bench.agents import agent_env_kwargs, load_agent
    from hbmp_bench.envs.behavior_env import BehaviorEnv
    from hbmp_bench.rollout import AgentFailed, EnvFailed, run_episode

    agent = load_agent(job.agent)
    options = {} if job.fidelity is None else {"fidelity": job.fidelity}
    env = BehaviorEnv(town=job.town, task=job.task, suite=job.suite, **options, **agent_env_kwargs(agent))
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


def run_jobs(jobs: Iterable[Job], workers: int = 1, progress: bool = True) -> list[EpisodeRecord]:
    """Run jobs' episodes in ``workers`` isolated slots (agent and simulation in their own processes);
    records come back ordered like the jobs. A failing agent gives ``agent_error`` records.
    Each agent is built once first (sandboxed, ``describe_agent``) for the env it asks for; the
    agents asking for the same env share one pool."""
    from hbmp_bench.evaluation.evaluate import iter_outcomes
    from hbmp_bench.evaluation.tasks import EpisodeTask, RunnerLimits, default_fidelity

    jobs = list(jobs)
    fidelity = default_fidelity()
    tasks = [EpisodeTask(j.suite, j.town, j.task, i, j.agent, j.fidelity or fidelity) for j in jobs for i in j.episodes]
    limits_of = {agent: agent_limits(agent, RunnerLimits()) for agent in dict.fromkeys(t.agent for t in tasks)}
    records = []
    for limits in dict.fromkeys(limits_of.values()):
        share = [t for t in tasks if limits_of[t.agent] == limits]
        records += [o.record for o in iter_outcomes(share, workers=workers, limits=limits, progress=progress)]
    order = {t.key: k for k, t in enumerate(tasks)}
    return sorted(records, key=lambda r: order.get(r.key, len(order)))


def agent_limits(agent: str, limits: "RunnerLimits") -> "RunnerLimits":
    """``limits`` with the env ``agent`` asks for (``evaluate.with_agent_env``); unchanged when the
    agent cannot be built (its episodes then fail as ``agent_error`` where they run)."""
    from hbmp_bench.evaluation.evaluate import with_agent_env
    from hbmp_bench.evaluation.pool import AgentBuildError, describe_agent

    try:
        description = describe_agent(agent, limits)
    except AgentBuildError:
        return limits
    return with_agent_env(limits, description)
