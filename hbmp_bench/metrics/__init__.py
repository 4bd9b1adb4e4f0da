"""Metric detectors, episode records and pandas summaries (reports: ``hbmp_bench.metrics.report``).

``summarize`` and ``success_table`` load on first access (they import pandas).
"""

from hbmp_bench._lazy import lazy_exports
from hbmp_bench.metrics.detectors import EVENT_KINDS, EgoFrame, InfractionDetector, StepEvents
from hbmp_bench.metrics.geometry import LaneLocator
from hbmp_bench.metrics.records import (
    EpisodeRecord,
    append_record,
    driving_score,
    latest_per_key,
    read_records,
    repair_records,
)

__all__ = [
    "EVENT_KINDS",
    "EgoFrame",
    "EpisodeRecord",
    "InfractionDetector",
    "LaneLocator",
    "StepEvents",
    "append_record",
    "driving_score",
    "latest_per_key",
    "read_records",
    "repair_records",
    "success_table",
    "summarize",
]

__getattr__, __dir__ = lazy_exports(__name__, {".summary": ("summarize", "success_table")})
