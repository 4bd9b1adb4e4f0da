"""Episode records: one row per episode, stored append-only as JSON lines."""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from dataclasses import MISSING, asdict, dataclass, fields
from pathlib import Path

from hbmp_bench.errors import UserError

PENALTIES = {
    "collision_pedestrian": 0.50,
    "collision_vehicle": 0.60,
    "red_light": 0.70,
}
"""CARLA Leaderboard 1.0 infraction penalty factors (multiplied once per event)."""

PENALTIES_LB2 = {
    "collision_pedestrian": 0.50,
    "collision_vehicle": 0.60,
    "collision_other": 0.65,
    "red_light": 0.70,
    "timeout": 0.70,
}
"""CARLA Leaderboard 2.0 infraction penalty factors (once per event): its pedestrian, vehicle and static
collisions and red lights; ``timeout`` is its scenario timeout (an episode of the scenario suites is one
scenario: a timeout is being blocked in it). Its stop-sign (0.8) and emergency-vehicle (0.7) penalties
have no event here: no town has stop signs, no scenario type an emergency vehicle."""

DRIVING_SCORE_LB2_DEFINITION = (
    "driving score LB 2.0 (0-100) = route completion % x the product of "
    + ", ".join(f"{factor:g} per {kind.replace('_', ' ')}" for kind, factor in PENALTIES_LB2.items())
    + " (CARLA Leaderboard 2.0)")


def driving_score_lb2(route_completion: float, counts: dict[str, int]) -> float:
    """CARLA Leaderboard 2.0 driving score [0, 100] of an episode: completion % × the product of
    :data:`PENALTIES_LB2` (``counts``: events per kind; ``timeout`` 0 or 1)."""
    penalty = 1.0
    for kind, factor in PENALTIES_LB2.items():
        penalty *= factor ** int(counts.get(kind, 0))
    return 100.0 * route_completion * penalty


def record_driving_score_lb2(row) -> float:
    """:func:`driving_score_lb2` of an episode record, or of a row with its fields (a results file's
    episode, a report frame's row): ``route_completion``, the collision and red-light counts, ``timeout``."""
    counts = {kind: row[kind] for kind in PENALTIES_LB2 if kind != "timeout"}
    return driving_score_lb2(row["route_completion"], {**counts, "timeout": int(bool(row["timeout"]))})


DRIVING_SCORE_DEFINITION = (
    "driving score (0-100) = route completion % x infraction penalty, the product of "
    + ", ".join(f"{factor:g} per {kind.replace('_', ' ')}" for kind, factor in PENALTIES.items())
    + " (CARLA Leaderboard 1.0)")
"""One-line definition of :func:`driving_score` for printed tables and legends."""

AGENT_ERROR = "agent_error"
"""end_reason of an episode whose agent raised, hung past the decision timeout, died, broke the
channel's protocol (a malformed, oversized or unsolicited reply) or returned an invalid action:
a failed episode of that agent (success false, driving score 0), counted in every table."""
SIM_ERROR = "sim_error"
"""end_reason of an episode the simulation could not finish (SUMO error, crash, watchdog) even
after a retry: not counted as the agent's episode, but shown as a count in every report; a
resumed evaluation runs it again, and a leaderboard entry with one is not ranked."""
DECISION_CAP = "decision_cap"
"""end_reason of an episode stopped after a fixed number of decisions (smoke runs)."""
END_REASON_ERRORS = (AGENT_ERROR, SIM_ERROR, DECISION_CAP)


@dataclass(frozen=True)
class EpisodeRecord:
    """The outcome of one episode (the DESIGN contract's columns).

    Distances in [m], durations in [s], counts are events (one per entry). ``end_reason`` is the
    world's (``goal``, ``timeout``, ``collision``, ``violation``, ``left_network``) or one of
    ``END_REASON_ERRORS`` set by the evaluation runner, with the reason in ``error``.
    ``traffic_vehicles`` / ``traffic_pedestrians``: the background vehicles and pedestrians put into
    the simulation at the episode's start (SUMO inserts a vehicle whose place is taken as soon as it is
    free; a pedestrian without a walk between its edges is left out: what spawned, not what the episode
    asked for). ``peak_lateral_accel_mps2``: the largest speed × yaw rate over any 1 s of the episode [m/s²]
    (:class:`~hbmp_bench.metrics.episode.LateralAcceleration`). -1: not recorded (an error record, the
    highway-env transfer, a record older than the field).

    A multi-agent episode (``Suite.agents`` > 1) has one record per goal-directed vehicle: ``vehicle`` names it
    (``ego``, ``ego1`` ...) and ``agent_collisions`` lists, space-separated, the other goal-directed vehicles of
    the scene it collided with (their collisions are also in ``collision_vehicle``); a pair that collided is in
    both records, so pairs are counted once by :func:`agent_collision_pairs`. Both are "" in a single-ego episode.
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
    error: str = ""
    traffic_vehicles: int = -1
    traffic_pedestrians: int = -1
    peak_lateral_accel_mps2: float = -1.0
    vehicle: str = ""
    agent_collisions: str = ""

    @property
    def collisions(self) -> int:
        return self.collision_vehicle + self.collision_pedestrian + self.collision_other

    @property
    def key(self) -> tuple[str, str, str, int, str, str]:
        """Identity of the episode run: (suite, town, task, episode, agent, fidelity)."""
        return (self.suite, self.town, self.task, self.episode, self.agent, self.fidelity)

    def to_dict(self) -> dict:
        return asdict(self)


def agent_collision_pairs(records) -> set[tuple[str, str, str, str, int, str, str]]:
    """The pairs of goal-directed vehicles that collided in multi-agent episodes, each once: (suite, town,
    task, agent, episode, first vehicle, second vehicle), from the records' ``agent_collisions`` (a pair is
    in both its vehicles' records, and in either alone when the other's record is missing)."""
    pairs = set()
    for r in records:
        for other in r.agent_collisions.split():
            first, second = sorted((r.vehicle, other))
            pairs.add((r.suite, r.town, r.task, r.agent, r.episode, first, second))
    return pairs


def driving_score(route_completion: float, counts: dict[str, int], off_route_fraction: float = 0.0) -> float:
    """CARLA Leaderboard driving score [0, 100]: completion % × product of infraction penalties."""
    penalty = 1.0
    for kind, factor in PENALTIES.items():
        penalty *= factor ** counts.get(kind, 0)
    penalty *= 1.0 - min(max(off_route_fraction, 0.0), 1.0)
    return 100.0 * route_completion * penalty


def record_line(record: EpisodeRecord) -> str:
    """The JSON line ``append_record`` writes for ``record`` (newline included)."""
    return json.dumps(record.to_dict(), sort_keys=True) + "\n"


def append_record(path: str | Path, record: EpisodeRecord) -> None:
    """Append one record as a single JSON line, flushed and fsynced (a crash never leaves half a line
    that ``read_records`` would accept)."""
    line = record_line(record)
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(line)
        fh.flush()
        os.fsync(fh.fileno())


def repair_records(path: str | Path) -> int:
    """Cut a torn last line (a kill mid-write) so the next append starts on a fresh line.

    Returns the number of bytes removed (0 when the file is whole or missing).
    """
    path = Path(path)
    if not path.exists():
        return 0
    with open(path, "rb+") as fh:
        data = fh.read()
        if not data or data.endswith(b"\n"):
            return 0
        keep = data.rfind(b"\n") + 1
        fh.truncate(keep)
        fh.flush()
        os.fsync(fh.fileno())
    return len(data) - keep


def latest_per_key(records: Iterable[EpisodeRecord]) -> list[EpisodeRecord]:
    """One record per ``EpisodeRecord.key``: the last one written wins (a rerun of a ``sim_error``
    replaces it), in first-seen order."""
    latest: dict[tuple, EpisodeRecord] = {}
    for record in records:
        latest[record.key] = record
    return list(latest.values())


def read_records(path: str | Path) -> list[EpisodeRecord]:
    """Records of a JSON-lines file; a torn last line (from a kill mid-write) is ignored. A line that is
    JSON but no episode record (another kind of file) raises ValueError naming the file and line."""
    with open(path, encoding="utf-8") as fh:
        try:
            return parse_records(fh)
        except ValueError as err:
            raise UserError(f"{path}: {err} (not an episode records file?)") from None


def parse_records(lines: Iterable[str]) -> list[EpisodeRecord]:
    """Records of JSON lines (``read_records`` without the file); lines that are not JSON are skipped,
    a JSON line without a record's fields raises ValueError."""
    names = {f.name for f in fields(EpisodeRecord)}
    required = {f.name for f in fields(EpisodeRecord) if f.default is MISSING and f.default_factory is MISSING}
    out = []
    for number, line in enumerate(lines, 1):
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            continue
        if not isinstance(row, dict) or not required <= row.keys():
            raise UserError(f"line {number} is not an episode record")
        out.append(EpisodeRecord(**{k: v for k, v in row.items() if k in names}))
    return out
