"""Running agents over episodes and suites: isolated, resumable, on processes or Ray.

- ``evaluate``: a suite selection for one agent, records appended as episodes finish, resumable.
- ``EpisodePool``: per slot an env process (SUMO) and an agent process joined by a pipe.
- ``ray_imap``: the same slots as Ray actors.
- ``run_job`` (in this process) / ``run_jobs`` (isolated): quick runs of a few episodes.
"""

from hbmp_bench.evaluation.evaluate import (BACKENDS, EvaluationInterrupted, EvaluationResult, evaluate, iter_outcomes,
                                            records_path)
from hbmp_bench.evaluation.pool import EpisodeOutcome, EpisodePool
from hbmp_bench.evaluation.runner import Job, run_job, run_jobs
from hbmp_bench.evaluation.tasks import EpisodeTask, RunnerLimits, agent_slug, default_fidelity, suite_tasks

__all__ = [
    "BACKENDS",
    "EpisodeOutcome",
    "EpisodePool",
    "EpisodeTask",
    "EvaluationInterrupted",
    "EvaluationResult",
    "Job",
    "RunnerLimits",
    "agent_slug",
    "default_fidelity",
    "evaluate",
    "iter_outcomes",
    "records_path",
    "run_job",
    "run_jobs",
    "suite_tasks",
]
