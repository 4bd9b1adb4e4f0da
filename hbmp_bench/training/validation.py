"""Greedy validation of a PPO run's policy on held-out episodes of the training town.

Training success (``episodes.csv``) is the *sampled* policy's: PPO explores by drawing behaviors from
π, while every agent is evaluated by its most likely behavior. The two can disagree by tens of points
(the shipped ``il`` reaches the goal in ~55 % of its sampled Town03 training episodes and in > 95 % of
the ``hbmp`` suite's Town03 Navigation episodes), so the sampled curve cannot say whether PPO has
improved the greedy policy, nor which checkpoint to ship.

Every ``validate_every`` episodes the run evaluates its current actor on the ``hbmp-val`` suite
(Town03 Navigation and Navigation dynamic, the first 20 of 50 each unless told, the paper's protocol,
episodes drawn from their own seed: not the test suites' episodes) with the package's evaluator (isolated
processes, as ``evaluate`` runs agents; the actor is the run's own, written by the trainer a moment before, so it
is trusted: no namespace sandbox, which a host without bubblewrap could not give), appends a row to
``validation.csv`` and writes the actor to ``best.pt`` when it ranks best so far (:func:`validation_rank`: success,
then route completion; ties: the later one). A fresh run validates its initial actor first (episode 0), so
the ``il`` baseline is the first row. The training workers wait meanwhile; 40 continuous episodes take
41-57 s with 2 slots on a quiet 2-core machine (4-7 min where other work ran beside).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from hbmp_bench.vocabulary import COLLISION_KINDS

VALIDATION_SUITE = "hbmp-val"
VALIDATION_COLUMNS = ("episode", "success", "success_navigation", "success_navigation_dynamic", "route_completion",
                      "red_light", "collision", "wrong_lane", "timeout", "episodes", "wall_s")
"""``validation.csv``: the run's episode count when validated, success over all validation episodes and
per task, mean route completion, the episodes ending with each failure kind, how many episodes, and the
validation's wall time [s]."""


DEFAULT_EPISODES_PER_TASK = 20
"""Validation episodes per task unless a run says otherwise: ``hbmp-val`` has 50 per task, drawn one generator
per episode, so its first 20 are the episodes it had when it had 20 (every earlier ``validation.csv``)."""


def validate(policy: str, workers: int, fidelity: str | None = None, episodes: int | None = None,
             progress: bool = False) -> dict[str, Any]:
    """Evaluate the checkpoint ``policy`` greedily on :data:`VALIDATION_SUITE`: its first ``episodes``
    episodes per task (None: :data:`DEFAULT_EPISODES_PER_TASK`), in ``workers`` evaluation slots, in
    ``fidelity`` (None: the default). ``policy`` is trusted (``RunnerLimits(trust_agent=True)``): it is
    the training run's own actor, not a submission.

    Returns the columns of :data:`VALIDATION_COLUMNS` but ``episode``.
    """
    import time

    from hbmp_bench.evaluation import Job, RunnerLimits, run_jobs
    from hbmp_bench.scenarios import get_suite

    suite = get_suite(VALIDATION_SUITE)
    start = time.perf_counter()
    count = min(DEFAULT_EPISODES_PER_TASK if episodes is None else episodes, suite.episodes_per_task)
    jobs = [Job(suite.name, town, task, policy, tuple(range(count)), fidelity)
            for town in suite.towns for task in suite.tasks]
    records = run_jobs(jobs, workers=workers, progress=progress, limits=RunnerLimits(trust_agent=True))

    def rate(rows) -> float:
        return round(float(np.mean([r.success for r in rows])), 4) if rows else float("nan")

    return {
        "success": rate(records),
        "success_navigation": rate([r for r in records if r.task == "Navigation"]),
        "success_navigation_dynamic": rate([r for r in records if r.task == "NavigationDynamic"]),
        "route_completion": round(float(np.mean([r.route_completion for r in records])), 4),
        "red_light": sum(r.red_light > 0 for r in records),
        "collision": sum(sum(getattr(r, k) for k in COLLISION_KINDS) > 0 for r in records),
        "wrong_lane": sum(r.wrong_lane > 0 for r in records),
        "timeout": sum(bool(r.timeout) for r in records),
        "episodes": len(records),
        "wall_s": round(time.perf_counter() - start, 1),
    }


def validation_rank(success: float, route_completion: float) -> tuple[float, float]:
    """How validations are ranked for ``best.pt``: by success, then by mean route completion (a policy that reaches
    no goal, e.g. ``flat`` from a random actor, is still told apart by how far it drives); equal ranks go to the later
    actor."""
    return (float(success), float(route_completion))


def validation_results(out: str) -> dict[str, str]:
    """Model-card lines of a run's ``validation.csv``: its first, best and last rows (empty without one)."""
    from hbmp_bench.training.runlog import read_csv

    path = os.path.join(out, "validation.csv")
    rows = read_csv(path) if os.path.isfile(path) else {}
    if not rows:
        return {}
    episode, success = rows["episode"], rows["success"]
    ranks = [validation_rank(s, c) for s, c in zip(success, rows["route_completion"])]
    best = max(range(len(ranks)), key=lambda i: (ranks[i], i))
    line = lambda i: f"{success[i]:.1%} at episode {int(episode[i])}"  # noqa: E731
    return {f"greedy success on {VALIDATION_SUITE}, first": line(0),
            f"greedy success on {VALIDATION_SUITE}, best (best.pt)": line(best),
            f"greedy success on {VALIDATION_SUITE}, last": line(len(success) - 1)}


class Validator:
    """The run's validation schedule, ``validation.csv`` and ``best.pt``.

    Args:
        out: the run folder.
        every: validate every this many episodes (0: never).
        workers: evaluation slots.
        episodes: validation episodes per task (None: :data:`DEFAULT_EPISODES_PER_TASK`).
        fidelity: the training env's fidelity.
        resumed_at: the episode count a resumed run continues from (rows after it are dropped); None
            for a fresh run.
    """

    def __init__(self, out: str, every: int, workers: int, fidelity: str | None, resumed_at: int | None,
                 episodes: int | None = None):
        from hbmp_bench.training.runlog import CsvLog, read_csv

        self.out, self.every, self.workers, self.fidelity, self.episodes = out, every, workers, fidelity, episodes
        self.log = CsvLog(os.path.join(out, "validation.csv"), VALIDATION_COLUMNS, keep_through=resumed_at) \
            if every > 0 else None
        done = read_csv(os.path.join(out, "validation.csv")) if self.log is not None else {}
        episodes = list(done.get("episode", []))
        ranks = [validation_rank(s, c) for s, c in zip(done.get("success", []), done.get("route_completion", []))]
        self.best_rank = max(ranks) if ranks else (-1.0, -1.0)
        self.last = int(max(episodes)) if episodes else None

    @property
    def best(self) -> float:
        """Success of the best validation so far (``best.pt``'s); -1 before the first."""
        return self.best_rank[0]

    def due(self, episodes: int) -> bool:
        """Whether the run should validate at this episode count (first call of a fresh run: yes)."""
        if self.log is None:
            return False
        return self.last is None or episodes >= self.last + self.every

    def __call__(self, episodes: int, checkpoint: dict[str, Any]) -> dict[str, Any]:
        """Validate ``checkpoint`` (the run at ``episodes``), log it, keep it as ``best.pt`` if best."""
        import tempfile

        from hbmp_bench.policies.checkpoints import actor_only, save_checkpoint

        actor = actor_only(checkpoint)
        with tempfile.TemporaryDirectory(prefix="hbmp-validation-") as folder:
            policy = os.path.join(folder, "policy.pt")
            save_checkpoint(policy, actor)
            row = {"episode": episodes, **validate(policy, self.workers, self.fidelity, self.episodes)}
        self.log.write(row)
        self.last = episodes
        rank = validation_rank(row["success"], row["route_completion"])
        if rank >= self.best_rank:
            self.best_rank = rank
            save_checkpoint(os.path.join(self.out, "best.pt"), actor)
        return row

    def close(self) -> None:
        if self.log is not None:
            self.log.close()
