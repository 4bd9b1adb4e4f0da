"""Episode records: one row per episode, stored append-only as JSON lines."""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, fields
from pathlib import Path

PENALTIES = {
    "collision_pedestrian": 0.50,
    "collision_vehicle": 0.60,
    "red_light": 0.70,
}
"""CARLA Leaderboard 1.0 infraction penalty factors (multiplied once per event)."""


@dataclass(frozen=True)
class EpisodeRecord:
    """The outcome of one episode (the DESIGN contract's columns).

    Distances in [m], durations in [s], counts are events (one per entry).
    """

    suite: str
    town: str
    task: str
    episode: int
    seed: int
    agent: str
    package_version: str
    fidelity: str
    success: bool
    route_completion: float
    collision_vehicle: int
    collision_pedestrian: int
    collision_other: int
    wrong_lane: int
    off_road: int
    red_light: int
    timeout: bool
    duration_s: float
    distance_m: float
    route_length_m: float
    decisions: int
    driving_score: float
    end_reason: str

    @property
    def collisions(self) -> int:
        return self.collision_vehicle + self.collision_pedestrian + self.collision_other

    def to_dict(self) -> dict:
        return asdict(self)


def driving_score(route_completion: float, counts: dict[str, int], off_route_fraction: float = 0.0) -> float:
    """CARLA Leaderboard driving score [0, 100]: completion % × product of infraction penalties."""
    penalty = 1.0
    for kind, factor in PENALTIES.items():
        penalty *= factor ** counts.get(kind, 0)
    penalty *= 1.0 - min(max(off_route_fraction, 0.0), 1.0)
    return 100.0 * route_completion * penalty


def append_record(path: str | Path, record: EpisodeRecord) -> None:
    """Append one record as a single JSON line, flushed and fsynced (a crash never leaves half a line
    that ``read_records`` would accept)."""
    line = json.dumps(record.to_dict(), sort_keys=True) + "\n"
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(line)
        fh.flush()
        os.fsync(fh.fileno())


def read_records(path: str | Path) -> list[EpisodeRecord]:
    """Records of a JSON-lines file; a torn last line (from a kill mid-write) is ignored."""
    names = {f.name for f in fields(EpisodeRecord)}
    out = []
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue
            out.append(EpisodeRecord(**{k: v for k, v in row.items() if k in names}))
    return out
