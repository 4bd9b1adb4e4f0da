"""Infraction and outcome detectors, run every simulation step on the ego's footprint.

The ego is judged against the route it follows, not against a simulator's map matching of its pose:

- **Collision**: the footprint overlaps another actor's (separating axes); once per contact.
- **Red light**: the front bumper's move during the step crosses the stop line of the lane the ego
  follows (the world's followed lane, whose link onto the route's next edge carries the signal)
  while that signal is red. The test intersects the bumper's segment between two samples with the
  stop-line segment across the lane, so it holds at any speed and only for the lane's own width: a
  pose far off its lane crosses no stop line.
- **Wrong lane / off-road**: a fraction of the footprint on lanes running the other way / on no
  lane and no junction. The junction is its polygon and its junction lanes' surface (an imported map's
  junction lanes can leave the polygon). One event per continuous entry: inside a junction (most of the
  footprint in it) the state is held, not judged; after an entry the state must stay clear for
  ``REARM_DISTANCE_M`` driven and ``REARM_TIME_S`` before a new entry counts, so jitter at a lane
  edge and the pass through a junction do not count twice.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hbmp_bench.metrics.geometry import (LaneLocator, box_corners, boxes_overlap, crosses_line, footprint_points,
                                        footprints_points)
from hbmp_bench.vocabulary import DETECTED_KINDS

WRONG_LANE_FRACTION = 0.3
"""Wrong lane: more than this fraction of the judged footprint on lanes running the other way (CoRL2017)."""
OFF_ROAD_FRACTION = 0.3
"""Off-road: more than this fraction of the judged footprint on no drivable lane and no junction."""
JUNCTION_HOLD_FRACTION = 0.5
"""Wrong lane and off-road are held (not judged) while more than this fraction of the footprint
lies inside junction polygons; elsewhere they are judged on the footprint outside junctions."""
REARM_DISTANCE_M = 5.0
"""After a wrong-lane or off-road entry, the state must be clear for this distance driven [m] ..."""
REARM_TIME_S = 1.0
"""... and for this long [s] before a new entry of the same kind counts."""
RED_STATES = frozenset("rRu")
"""Signal chars at which crossing the stop line is a red-light violation (``u``: red-yellow)."""

EVENT_KINDS = DETECTED_KINDS
"""The kinds a step's events count (:data:`~hbmp_bench.vocabulary.DETECTED_KINDS`)."""


@dataclass
class StepEvents:
    """What happened during one simulation step (counts of new events)."""

    collision_vehicle: int = 0
    collision_pedestrian: int = 0
    wrong_lane: int = 0
    off_road: int = 0
    red_light: int = 0
    goal_reached: bool = False
    timeout: bool = False
    collided_with: tuple[str, ...] = ()

    @property
    def collisions(self) -> int:
        return self.collision_vehicle + self.collision_pedestrian

    @property
    def violations(self) -> int:
        """Rule violations that end an episode under the paper's protocol."""
        return self.collisions + self.wrong_lane + self.off_road + self.red_light


@dataclass(frozen=True, eq=False)
class StopLine:
    """The stop line at the end of the lane the ego follows, with the signal of the link it takes there.

    Attributes:
        lane: id of the approach lane the line ends.
        ends: (2, 2) the line's right and left end [m], across the lane's width.
        direction: (2,) unit travel direction at the line.
        signal: the link's signal char now (``r``, ``y``, ``g``, ``G`` ...).
    """

    lane: str
    ends: np.ndarray
    direction: np.ndarray
    signal: str


@dataclass
class EgoFrame:
    """The ego at one step.

    Attributes:
        xy: (2,) footprint centre [m].
        yaw: heading [rad].
        length / width: footprint [m].
        stop_line: the signalised stop line ahead on the lane the ego follows, None where that lane's
            link is not signalised (or the ego follows no lane).
        edge: the edge of the lane the ego follows (its lanes win where lanes overlap in plan view),
            "" if none.
    """

    xy: np.ndarray
    yaw: float
    length: float
    width: float
    stop_line: StopLine | None = None
    edge: str = ""


@dataclass
class _Latch:
    """One event per continuous entry: rises once, falls after being clear for a distance and a time."""

    active: bool = False
    clear_m: float = 0.0
    clear_since_s: float = np.inf

    def update(self, state: bool | None, moved_m: float, time_s: float) -> int:
        """``state``: True (in violation), False (clear), None (cannot judge: hold). Returns 1 on a new entry."""
        if state is None:
            return 0
        if state:
            self.clear_m, self.clear_since_s = 0.0, np.inf
            if self.active:
                return 0
            self.active = True
            return 1
        if self.active:
            if not np.isfinite(self.clear_since_s):
                self.clear_since_s = time_s
            self.clear_m += moved_m
            if self.clear_m >= REARM_DISTANCE_M and time_s - self.clear_since_s >= REARM_TIME_S:
                self.active = False
        return 0


@dataclass
class InfractionDetector:
    """Stateful per-episode detector. Call ``update`` every step (a new detector per episode).

    Args:
        locator: lane lookup of the episode's network.
        goal_xy: (2,) goal point [m].
        success_radius_m: goal reached within this distance of the ego centre [m].
        timeout_s: episode time limit [s].
    """

    locator: LaneLocator
    goal_xy: np.ndarray
    success_radius_m: float
    timeout_s: float
    totals: dict[str, int] = field(default_factory=lambda: dict.fromkeys(EVENT_KINDS, 0))
    _touching: frozenset[str] = frozenset()
    _wrong: _Latch = field(default_factory=_Latch)
    _off: _Latch = field(default_factory=_Latch)
    _xy: np.ndarray | None = None
    _front: np.ndarray | None = None
    _stop_line: StopLine | None = None
    _red_lane: str = ""

    def update(self, ego: EgoFrame, others_ids, others_xy, others_yaw, others_len, others_wid, others_ped, time_s: float) -> StepEvents:
        """Detect this step's events; ``others_*`` are (K,) arrays of the other actors, ``time_s`` [s]."""
        near = np.hypot(*(others_xy - ego.xy).T) < (ego.length + others_len) if len(others_ids) else np.zeros(0, bool)
        hits: list[tuple[str, bool]] = []
        if near.any():
            box = box_corners(ego.xy[None], np.array([ego.yaw]), np.array([ego.length]), np.array([ego.width]))[0]
            idx = np.nonzero(near)[0]
            hit = boxes_overlap(box, box_corners(others_xy[idx], others_yaw[idx], others_len[idx], others_wid[idx]))
            hits = [(others_ids[i], bool(others_ped[i])) for i in idx[hit]]
        heading = np.array([np.cos(ego.yaw), np.sin(ego.yaw)])
        points = footprint_points(ego.xy, ego.yaw, ego.length, ego.width)
        located = self.locator.locate(points, prefer_edge=ego.edge)
        return self._events(ego, heading, hits, _lane_state(located, heading), time_s)

    def _events(self, ego: EgoFrame, heading: np.ndarray, hits: list[tuple[str, bool]],
                lane_state: tuple[bool | None, bool | None], time_s: float) -> StepEvents:
        """The step's events from what the footprint touches (``hits``: (actor id, is pedestrian) of every
        overlapping actor) and its lane state (:func:`_lane_state`); updates the detector's state."""
        ev = StepEvents()
        touching = set()
        for actor, pedestrian in hits:
            touching.add(actor)
            if actor not in self._touching:
                if pedestrian:
                    ev.collision_pedestrian += 1
                else:
                    ev.collision_vehicle += 1
        ev.collided_with = tuple(sorted(touching - self._touching))
        self._touching = frozenset(touching)

        moved_m = 0.0 if self._xy is None else float(np.hypot(*(ego.xy - self._xy)))
        wrong, off = lane_state
        ev.wrong_lane = self._wrong.update(wrong, moved_m, time_s)
        ev.off_road = self._off.update(off, moved_m, time_s)

        front = ego.xy + heading * (ego.length / 2)
        ran = self._ran_red(self._front, front, ego.stop_line) if self._front is not None else ""
        ev.red_light = int(bool(ran))
        following = ego.stop_line.lane if ego.stop_line is not None else ""
        self._red_lane = ran or (self._red_lane if following == self._red_lane else "")
        self._xy, self._front, self._stop_line = ego.xy, front, ego.stop_line

        ev.goal_reached = bool(np.hypot(*(ego.xy - self.goal_xy)) <= self.success_radius_m)
        ev.timeout = time_s >= self.timeout_s
        for kind in EVENT_KINDS:
            self.totals[kind] += getattr(ev, kind)
        return ev

    def _ran_red(self, front_before: np.ndarray, front: np.ndarray, line: StopLine | None) -> str:
        """The lane whose red stop line the front bumper's move crossed, else "".

        The line followed before the step is judged with the signal it showed then; a different line
        followed now (a lane change onto it during the step) with its signal now. A line already run
        is not counted again while the car still follows it (stopping on it, rolling back over it)."""
        lines = [self._stop_line] if self._stop_line is not None else []
        if line is not None and (not lines or line.lane != lines[0].lane):
            lines.append(line)
        for ln in lines:
            if ln.lane != self._red_lane and ln.signal in RED_STATES and crosses_line(front_before, front, ln.ends, ln.direction):
                return ln.lane
        return ""


def _lane_state(located: tuple[np.ndarray, np.ndarray, np.ndarray], heading: np.ndarray) -> tuple[bool | None, bool | None]:
    """(wrong lane, off-road) of a footprint from its points' lane lookup ``located`` (lane (P,), direction
    (P, 2), in_junction (P,): :meth:`~hbmp_bench.metrics.geometry.LaneLocator.locate`) and the heading (2,);
    (None, None) while it is mostly in a junction."""
    lane, direction, in_junction = located
    judged = ~in_junction
    n = int(judged.sum())
    if n <= (1.0 - JUNCTION_HOLD_FRACTION) * len(lane):
        return None, None
    on_lane = lane >= 0
    against = judged & on_lane & (direction @ heading < 0.0)
    off = judged & ~on_lane
    return bool(against.sum() > WRONG_LANE_FRACTION * n), bool(off.sum() > OFF_ROAD_FRACTION * n)


def update_all(detectors: list[InfractionDetector], frames: list[EgoFrame], ids, xy, yaw, length, width,
               is_pedestrian, visible: np.ndarray, time_s: float) -> list[StepEvents]:
    """:meth:`InfractionDetector.update` of N vehicles in one pass: the same events and detector states
    as one call per vehicle (tested), with the contact test, the footprints and their lane lookup done
    for all N at once.

    Args:
        detectors / frames: (N,) each vehicle's detector and its frame now.
        ids, xy, yaw, length, width, is_pedestrian: (K,) every actor now (the snapshot, the N vehicles
            among them).
        visible: (N, K) bool, the actors vehicle ``n`` can meet (``Actors.around``: itself excluded).
        time_s: simulation time [s].
    """
    n = len(frames)
    if n == 0:
        return []
    ego_xy = np.array([f.xy for f in frames], dtype=float).reshape(n, 2)
    ego_yaw = np.array([f.yaw for f in frames], dtype=float)
    ego_len = np.array([f.length for f in frames], dtype=float)
    ego_wid = np.array([f.width for f in frames], dtype=float)
    hits: list[list[tuple[str, bool]]] = [[] for _ in range(n)]
    if len(ids):
        dist = np.hypot(xy[None, :, 0] - ego_xy[:, 0:1], xy[None, :, 1] - ego_xy[:, 1:2])
        near = (dist < ego_len[:, None] + length[None, :]) & visible
        rows, cols = np.nonzero(near)
        if len(rows):
            boxes = box_corners(ego_xy[rows], ego_yaw[rows], ego_len[rows], ego_wid[rows])
            hit = boxes_overlap(boxes, box_corners(xy[cols], yaw[cols], length[cols], width[cols]))
            for r, c in zip(rows[hit].tolist(), cols[hit].tolist()):
                hits[r].append((ids[c], bool(is_pedestrian[c])))
    points = footprints_points(ego_xy, [f.yaw for f in frames], [f.length for f in frames], [f.width for f in frames])
    located = detectors[0].locator.locate_all(points, [f.edge for f in frames])
    out = []
    for k, (detector, frame) in enumerate(zip(detectors, frames)):
        heading = np.array([np.cos(frame.yaw), np.sin(frame.yaw)])
        state = _lane_state((located[0][k], located[1][k], located[2][k]), heading)
        out.append(detector._events(frame, heading, hits[k], state, time_s))
    return out
