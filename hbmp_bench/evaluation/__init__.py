"""Running agents over episodes and suites."""

from hbmp_bench.evaluation.runner import Job, run_job, run_jobs

__all__ = ["Job", "run_job", "run_jobs"]
