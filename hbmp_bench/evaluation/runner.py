"""Run agents on episodes and collect records (one process here; pools in ``run_jobs``)."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass

from hbmp_bench.agents import load_agent
from hbmp_bench.envs.behavior_env import BehaviorEnv
from hbmp_bench.metrics.records import EpisodeRecord


@dataclass(frozen=True)
class Job:
    """Episodes of one (suite, town, task) for one agent."""

    suite: str
    town: str
    task: str
    agent: str
    episodes: tuple[int, ...]
    fidelity: str = "event"


def run_job(job: Job) -> tuple[list[EpisodeRecord], float, int]:
    """Run a job's episodes in this process; returns (records, wall seconds, decisions)."""
    env = BehaviorEnv(town=job.town, task=job.task, suite=job.suite, fidelity=job.fidelity)
    agent = load_agent(job.agent)
    records, decisions = [], 0
    start = time.perf_counter()
    try:
        for index in job.episodes:
            obs, info = env.reset(seed=index, options={"episode_index": index})
            agent.reset(info)
            while True:
                obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
                decisions += 1
                if terminated or truncated:
                    break
            records.append(dataclasses.replace(EpisodeRecord(**info["episode"]), agent=job.agent))
    finally:
        env.close()
    return records, time.perf_counter() - start, decisions


def run_jobs(jobs: Iterable[Job], workers: int = 1, progress: bool = True) -> list[EpisodeRecord]:
    """Run jobs in ``workers`` processes (libsumo: one simulation per process)."""
    from tqdm import tqdm

    jobs = list(jobs)
    total = sum(len(j.episodes) for j in jobs)
    records: list[EpisodeRecord] = []
    bar = tqdm(total=total, unit="ep", disable=not progress)
    if workers <= 1:
        for job in jobs:
            recs, _, _ = run_job(job)
            records.extend(recs)
            bar.update(len(recs))
            bar.set_postfix(success=f"{sum(r.success for r in records) / len(records):.0%}")
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            for fut in as_completed([pool.submit(run_job, j) for j in jobs]):
                recs, _, _ = fut.result()
                records.extend(recs)
                bar.update(len(recs))
                bar.set_postfix(success=f"{sum(r.success for r in records) / len(records):.0%}")
    bar.close()
    order = {(j.town, j.task): k for k, j in enumerate(jobs)}
    records.sort(key=lambda r: (order.get((r.town, r.task), 0), r.episode))
    return records
