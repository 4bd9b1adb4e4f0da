"""Metric detectors, episode records and pandas summaries (reports: ``hbmp_bench.metrics.report``)."""

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
from hbmp_bench.metrics.summary import summarize, success_table

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
