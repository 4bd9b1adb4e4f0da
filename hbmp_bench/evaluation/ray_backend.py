"""Episodes as Ray work: one actor per worker, each holding a one-slot ``EpisodePool``.

Every actor keeps its env and agent processes across episodes (the same isolation, watchdog and
retries as the local pool) and runs one episode per call, so outcomes stream back as episodes
finish, in any order. Needs the ``ray`` extra (``pip install "hbmp-bench[ray]"``); every node of
a cluster needs the package (and the agent's module) installed.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator, Mapping

from hbmp_bench.evaluation.channel import AgentDescription
from hbmp_bench.evaluation.env_process import blank_records
from hbmp_bench.evaluation.pool import EpisodeOutcome, EpisodePool
from hbmp_bench.evaluation.tasks import EpisodeTask, RunnerLimits
from hbmp_bench.metrics.records import SIM_ERROR


def import_ray():
    """The ``ray`` module, or an ImportError that names the extra to install."""
    try:
        import ray
    except ImportError as exc:
        raise ImportError('the ray backend needs Ray: pip install "hbmp-bench[ray]"') from exc
    return ray


class EpisodeActor:
    """Ray actor body: a one-slot episode pool that lives as long as the actor."""

    def __init__(self, limits: RunnerLimits, descriptions: Mapping[str, AgentDescription] | None = None):
        self.pool = EpisodePool(1, limits, descriptions=descriptions)

    def run(self, task: EpisodeTask) -> EpisodeOutcome:
        (outcome,) = list(self.pool.imap([task]))
        return outcome

    def close(self) -> None:
        self.pool.close()


def ray_imap(
    tasks: Iterable[EpisodeTask],
    limits: RunnerLimits | None = None,
    *,
    workers: int | None = None,
    address: str | None = None,
    descriptions: Mapping[str, AgentDescription] | None = None,
) -> Iterator[EpisodeOutcome]:
    """Run ``tasks`` on Ray; yields one outcome per task in finishing order.

    Args:
        workers: actors (default: the cluster's CPUs, at most one per task).
        address: a running cluster (``ray://host:10001``, ``auto``); None starts a local instance
            unless Ray is already initialised in this process. A local instance started here is
            shut down at the end.
        descriptions: agents already described (see ``EpisodePool``); each actor's pool
            describes the others itself.
    """
    ray = import_ray()
    limits = limits or RunnerLimits()
    pending = deque(tasks)
    if not pending:
        return
    started_here = not ray.is_initialized()
    if started_here:
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    actor_cls = ray.remote(num_cpus=1, max_restarts=0)(EpisodeActor)
    actors: list = []
    try:
        n = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        actors.extend(actor_cls.remote(limits, descriptions) for _ in range(min(n, len(pending))))
        attempts: dict[EpisodeTask, int] = {}
        running: dict = {}

        def submit(actor) -> None:
            task = pending.popleft()
            attempts[task] = attempts.get(task, 0) + 1
            running[actor.run.remote(task)] = (actor, task)

        for actor in actors:
            submit(actor)
        while running:
            (ref,), _ = ray.wait(list(running), num_returns=1)
            actor, task = running.pop(ref)
            try:
                outcome = ray.get(ref)
            except ray.exceptions.RayError as exc:
                ray.kill(actor)
                actor = actor_cls.remote(limits, descriptions)
                actors.append(actor)
                if attempts[task] <= limits.retries:
                    pending.appendleft(task)
                    outcome = None
                else:
                    reason = f"ray worker failed: {type(exc).__name__}: {str(exc)[:500]}"
                    outcome = EpisodeOutcome(blank_records(task, SIM_ERROR, reason), attempts[task], 0.0, 0.0)
            if pending:
                submit(actor)
            if outcome is not None:
                yield outcome
    finally:
        for actor in actors:
            ray.kill(actor)
        if started_here:
            ray.shutdown()
