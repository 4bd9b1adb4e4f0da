"""Detectors on crafted footprints placed on Town01's lane geometry (no SUMO)."""

import numpy as np
import pytest

from hbmp_bench.metrics import EgoFrame, InfractionDetector, LaneLocator
from hbmp_bench.metrics.geometry import box_corners, boxes_overlap
from hbmp_bench.scenarios import road_network

NET = road_network("Town01")
LOCATOR = LaneLocator(NET)


def _lane_pose(lane_id, pos):
    shape = NET.lane(lane_id).shape
    xy = NET.position(lane_id, pos)
    ahead = NET.position(lane_id, pos + 1.0)
    return xy, float(np.arctan2(*(ahead - xy)[::-1]))


def _two_way_edge():
    for edge, opposite in NET.opposite.items():
        if opposite and NET.edge_length[edge] > 60:
            return edge, opposite
    raise AssertionError("Town01 has two-way roads")


def _detector():
    return InfractionDetector(LOCATOR, goal_xy=np.array([1e6, 1e6]), success_radius_m=2.0, timeout_s=100.0)


def _update(det, ego, others=(), t=1.0):
    ids = tuple(o[0] for o in others)
    xy = np.array([o[1] for o in others]).reshape(-1, 2)
    yaw = np.array([o[2] for o in others], dtype=float)
    n = len(others)
    return det.update(ego, ids, xy, yaw, np.full(n, 4.5), np.full(n, 1.8), np.array([o[3] for o in others], dtype=bool), t)


def test_clean_driving_reports_nothing():
    edge, _ = _two_way_edge()
    det = _detector()
    lane = NET.edge_lanes[edge][0]
    for pos in np.arange(10.0, 50.0, 1.0):
        xy, yaw = _lane_pose(lane, pos)
        ev = _update(det, EgoFrame(xy, yaw, 4.5, 1.8))
        assert ev.violations == 0
    assert sum(det.totals.values()) == 0


def test_wrong_lane_counted_once_per_entry():
    edge, opposite = _two_way_edge()
    own = NET.edge_lanes[edge][0]
    other = NET.edge_lanes[opposite][0]
    det = _detector()
    xy, yaw = _lane_pose(own, 30.0)
    assert _update(det, EgoFrame(xy, yaw, 4.5, 1.8)).wrong_lane == 0
    # drive with our heading on the centre of the opposite lane for 5 steps: one event
    oxy, oyaw = _lane_pose(other, NET.lane(other).length - 30.0)
    for _ in range(5):
        _update(det, EgoFrame(oxy, oyaw + np.pi, 4.5, 1.8))
    assert det.totals["wrong_lane"] == 1
    _update(det, EgoFrame(xy, yaw, 4.5, 1.8))
    for _ in range(2):
        _update(det, EgoFrame(oxy, oyaw + np.pi, 4.5, 1.8))
    assert det.totals["wrong_lane"] == 2


def test_off_road_far_from_any_lane():
    det = _detector()
    lo = min(l.shape[:, 0].min() for l in NET.lanes.values())
    lo_y = min(l.shape[:, 1].min() for l in NET.lanes.values())
    ev = _update(det, EgoFrame(np.array([lo - 50.0, lo_y - 50.0]), 0.0, 4.5, 1.8))
    assert ev.off_road == 1 and ev.wrong_lane == 0


def test_collision_with_vehicle_and_pedestrian_counted_per_contact():
    edge, _ = _two_way_edge()
    lane = NET.edge_lanes[edge][0]
    xy, yaw = _lane_pose(lane, 30.0)
    det = _detector()
    car_xy, _ = _lane_pose(lane, 33.5)  # 3.5 m ahead: boxes of 4.5 m overlap
    for _ in range(3):
        ev = _update(det, EgoFrame(xy, yaw, 4.5, 1.8), [("car", car_xy, yaw, False)])
    assert det.totals["collision_vehicle"] == 1
    far_xy, _ = _lane_pose(lane, 45.0)
    ev = _update(det, EgoFrame(xy, yaw, 4.5, 1.8), [("car", far_xy, yaw, False), ("ped", xy + 0.5, 0.0, True)])
    assert ev.collision_pedestrian == 1 and ev.collision_vehicle == 0


def test_red_light_crossing_and_lane_change_at_red():
    edge, _ = _two_way_edge()
    xy, yaw = _lane_pose(NET.edge_lanes[edge][0], 30.0)
    det = _detector()
    _update(det, EgoFrame(xy, yaw, 4.5, 1.8, light=("J", 0, 2.0, "r")))
    ev = _update(det, EgoFrame(xy, yaw, 4.5, 1.8, light=("K", 3, 80.0, "G")))
    assert ev.red_light == 1
    # a different link far from the line (a lane change) is not a crossing; green crossing neither
    _update(det, EgoFrame(xy, yaw, 4.5, 1.8, light=("J", 0, 40.0, "r")))
    assert _update(det, EgoFrame(xy, yaw, 4.5, 1.8, light=("J", 1, 40.0, "r"))).red_light == 0
    _update(det, EgoFrame(xy, yaw, 4.5, 1.8, light=("J", 1, 1.0, "G")))
    assert _update(det, EgoFrame(xy, yaw, 4.5, 1.8, light=None)).red_light == 0
    assert det.totals["red_light"] == 1


def test_goal_and_timeout():
    det = InfractionDetector(LOCATOR, goal_xy=np.array([10.0, 0.0]), success_radius_m=2.0, timeout_s=5.0)
    assert not _update(det, EgoFrame(np.array([7.0, 0.0]), 0.0, 4.5, 1.8), t=1.0).goal_reached
    assert _update(det, EgoFrame(np.array([8.5, 0.0]), 0.0, 4.5, 1.8), t=1.0).goal_reached
    assert _update(det, EgoFrame(np.array([0.0, 0.0]), 0.0, 4.5, 1.8), t=5.0).timeout


def test_separating_axis_overlap():
    a = box_corners(np.array([[0.0, 0.0]]), np.array([0.0]), np.array([4.0]), np.array([2.0]))[0]
    others = box_corners(np.array([[3.9, 0.0], [4.1, 0.0], [0.0, 2.1], [2.5, 2.5]]), np.array([0.0, 0.0, 0.0, np.pi / 4]),
                         np.full(4, 4.0), np.full(4, 2.0))
    assert boxes_overlap(a, others).tolist() == [True, False, False, True]
