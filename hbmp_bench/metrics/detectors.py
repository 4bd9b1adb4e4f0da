"""Infraction and outcome detectors, run every simulation step on the ego's footprint.

Events are counted once per entry (a rising edge), not once per step: driving 3 s on the
opposite lane is one wrong-lane event; touching the same car for 10 steps is one collision.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hbmp_bench.metrics.geometry import LaneLocator, box_corners, boxes_overlap, footprint_points

WRONG_LANE_FRACTION = 0.3
"""Wrong lane: more than this fraction of the footprint on lanes running the other way (CoRL2017)."""
OFF_ROAD_FRACTION = 0.3
"""Off-road: more than this fraction of the footprint on no drivable lane and no junction."""
RED_STATES = frozenset("rR")
"""Signal chars that make crossing the stop line a red-light violation."""

STOP_LINE_REACH_M = 3.0
"""The stop line counts as crossed when the light ahead changes within this distance of it [m]
(farther away, a changed light ahead means a lane change, not a crossing)."""

EVENT_KINDS = ("collision_vehicle", "collision_pedestrian", "wrong_lane", "off_road", "red_light")


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


@dataclass
class EgoFrame:
    """The ego at one step: centre (2,) [m], yaw [rad], footprint [m], the next traffic light on its
    route as (tls, link index, distance [m], state) or None, and the edge it drives on ("" if unknown)."""

    xy: np.ndarray
    yaw: float
    length: float
    width: float
    light: tuple[str, int, float, str] | None = None
    edge: str = ""


@dataclass
class InfractionDetector:
    """Stateful per-episode detector. Call ``reset`` at episode start, ``update`` every step.

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
    _wrong: bool = False
    _off: bool = False
    _light: tuple[str, int, float, str] | None = None

    def update(self, ego: EgoFrame, others_ids, others_xy, others_yaw, others_len, others_wid, others_ped, time_s: float) -> StepEvents:
        """Detect this step's events; ``others_*`` are (K,) arrays of the other actors."""
        ev = StepEvents()
        box = box_corners(ego.xy[None], np.array([ego.yaw]), np.array([ego.length]), np.array([ego.width]))[0]
        near = np.hypot(*(others_xy - ego.xy).T) < (ego.length + others_len) if len(others_ids) else np.zeros(0, bool)
        touching = set()
        if near.any():
            idx = np.nonzero(near)[0]
            hit = boxes_overlap(box, box_corners(others_xy[idx], others_yaw[idx], others_len[idx], others_wid[idx]))
            touching = {others_ids[i] for i in idx[hit]}
            for i in idx[hit]:
                if others_ids[i] not in self._touching:
                    if others_ped[i]:
                        ev.collision_pedestrian += 1
                    else:
                        ev.collision_vehicle += 1
        ev.collided_with = tuple(sorted(touching - self._touching))
        self._touching = frozenset(touching)

        points = footprint_points(ego.xy, ego.yaw, ego.length, ego.width)
        lane, direction, in_junction = self.locator.locate(points, prefer_edge=ego.edge)
        heading = np.array([np.cos(ego.yaw), np.sin(ego.yaw)])
        on_lane = lane >= 0
        against = on_lane & ~in_junction & (direction @ heading < 0.0)
        wrong = against.mean() > WRONG_LANE_FRACTION
        off = (~on_lane & ~in_junction).mean() > OFF_ROAD_FRACTION
        ev.wrong_lane = int(wrong and not self._wrong)
        ev.off_road = int(off and not self._off)
        self._wrong, self._off = wrong, off

        previous, self._light = self._light, ego.light
        if previous is not None:
            moved_on = ego.light is None or ego.light[:2] != previous[:2] or ego.light[2] > previous[2] + 1.0
            if moved_on and previous[2] <= STOP_LINE_REACH_M and previous[3] in RED_STATES:
                ev.red_light = 1

        ev.goal_reached = bool(np.hypot(*(ego.xy - self.goal_xy)) <= self.success_radius_m)
        ev.timeout = time_s >= self.timeout_s
        for kind in EVENT_KINDS:
            self.totals[kind] += getattr(ev, kind)
        return ev
