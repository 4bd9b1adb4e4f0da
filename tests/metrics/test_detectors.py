"""Detectors on crafted footprints placed on Town01's lane geometry (no SUMO)."""

import numpy as np
import pytest

from hbmp_bench.maps.roadnet import point_along
from hbmp_bench.metrics import EgoFrame, InfractionDetector, LaneLocator
from hbmp_bench.metrics.detectors import REARM_DISTANCE_M, REARM_TIME_S, StopLine
from hbmp_bench.metrics.geometry import box_corners, boxes_overlap, crosses_line, footprint_points, points_in_polygon
from hbmp_bench.scenarios import road_network, suite_episodes

NET = road_network("Town01")
LOCATOR = LaneLocator(NET)
DT = 0.1


def _lane_pose(lane_id, pos):
    xy = NET.position(lane_id, pos)
    ahead = NET.position(lane_id, pos + 1.0)
    return xy, float(np.arctan2(*(ahead - xy)[::-1]))


def _two_way_edge():
    for edge, opposite in NET.opposite.items():
        if opposite and NET.edge_length[edge] > 60:
            return edge, opposite
    raise AssertionError("Town01 has two-way roads")


def _signalised_link():
    for conns in NET.connections.values():
        for c in conns:
            if c.tls and NET.lane(c.from_lane).length > 60:
                return c
    raise AssertionError("Town01 has traffic lights")


def _stop_line(lane, next_edge, signal):
    ends, direction, _, _ = LOCATOR.stop_line(lane, next_edge)
    return StopLine(lane, ends, direction, signal)


def _detector():
    return InfractionDetector(LOCATOR, goal_xy=np.array([1e6, 1e6]), success_radius_m=2.0, timeout_s=100.0)


def _update(det, ego, others=(), t=1.0):
    ids = tuple(o[0] for o in others)
    xy = np.array([o[1] for o in others]).reshape(-1, 2)
    yaw = np.array([o[2] for o in others], dtype=float)
    n = len(others)
    return det.update(ego, ids, xy, yaw, np.full(n, 4.5), np.full(n, 1.8), np.array([o[3] for o in others], dtype=bool), t)


def _route_drive(route, start_lane, start_pos, speed, left_offset=0.0, signal="G"):
    """EgoFrames of a car driving ``route`` along its lanes' centrelines (junction lanes included) at
    ``speed`` [m/s], ``left_offset`` [m] to the left of them, as the world builds them: the stop line of
    the last normal lane passed with ``signal``. Yields (frame, followed lane, time [s])."""
    lanes, lane = [start_lane], start_lane
    for edge in route[1:]:
        while True:
            lane = NET.follow(lane, edge)
            lanes.append(lane)
            if lane in NET.lanes:
                break
    shapes = [NET.lane(ln).shape for ln in lanes]
    starts = np.cumsum([0.0] + [np.hypot(*np.diff(s, axis=0).T).sum() for s in shapes])
    line = np.concatenate(shapes)
    line = line[np.concatenate([[True], np.hypot(*np.diff(line, axis=0).T) > 1e-6])]
    s, t = start_pos, 0.0
    while s + 1.0 < starts[-1]:
        xy, ahead = point_along(line, s), point_along(line, s + 1.0)
        yaw = float(np.arctan2(*(ahead - xy)[::-1]))
        xy = xy + left_offset * np.array([-np.sin(yaw), np.cos(yaw)])
        k = int(np.searchsorted(starts, s, side="right") - 1)
        followed = next(ln for ln in reversed(lanes[:k + 1]) if ln in NET.lanes)
        edge = NET.lane(followed).edge
        nxt = route[route.index(edge) + 1] if edge != route[-1] else None
        fixed = LOCATOR.stop_line(followed, nxt)
        stop = None if fixed is None else StopLine(followed, fixed[0], fixed[1], signal)
        yield EgoFrame(xy, yaw, 4.5, 1.8, stop, edge), followed, t
        s, t = s + speed * DT, t + DT


def _three_junction_episode():
    for ep in suite_episodes("corl2017", "Town01", "Straight"):
        if len(ep.route) >= 4 and all(NET.links(a, b)[0].tls for a, b in zip(ep.route[:-1], ep.route[1:])):
            return ep
    raise AssertionError("a Town01 Straight episode crosses three signalised junctions")


def _junction_passes(frames):
    """How many times the footprints enter a junction polygon with more than half their area."""
    inside = []
    for f in frames:
        points = footprint_points(f.xy, f.yaw, f.length, f.width)
        inside.append(LOCATOR.locate(points)[2].mean() > 0.5)
    return int(np.sum(np.diff(np.asarray(inside, dtype=int)) == 1))


def test_clean_driving_reports_nothing():
    edge, _ = _two_way_edge()
    det = _detector()
    lane = NET.edge_lanes[edge][0]
    for pos in np.arange(10.0, 50.0, 1.0):
        xy, yaw = _lane_pose(lane, pos)
        ev = _update(det, EgoFrame(xy, yaw, 4.5, 1.8))
        assert ev.violations == 0
    assert sum(det.totals.values()) == 0


def test_clean_drive_through_three_green_junctions_reports_nothing():
    ep = _three_junction_episode()
    det = _detector()
    lines = set()
    for frame, followed, t in _route_drive(ep.route, ep.start_lane, ep.start_pos, 10.0, signal="G"):
        assert _update(det, frame, t=t).violations == 0
        lines.add(frame.stop_line.lane if frame.stop_line else None)
    assert len(lines - {None}) >= 3  # three signalised stop lines were passed
    assert sum(det.totals.values()) == 0


def test_wrong_lane_counted_once_per_entry_with_hysteresis():
    edge, opposite = _two_way_edge()
    own, other = NET.edge_lanes[edge][0], NET.edge_lanes[opposite][0]
    det = _detector()
    t = 0.0

    def at(lane, pos, against):
        nonlocal t
        t += DT
        xy, yaw = _lane_pose(lane, pos)
        return _update(det, EgoFrame(xy, yaw + (np.pi if against else 0.0), 4.5, 1.8), t=t)

    length = NET.lane(own).length
    assert at(own, 10.0, False).wrong_lane == 0
    # 1 m per step along the road; the opposite lane's position runs the other way
    for k in range(5):
        at(other, length - 11.0 - k, True)
    assert det.totals["wrong_lane"] == 1
    # back on the own lane for 2 steps (2 m, 0.2 s: jitter at the lane edge), out again: same entry
    at(own, 16.0, False)
    at(own, 17.0, False)
    at(other, length - 18.0, True)
    assert det.totals["wrong_lane"] == 1
    # clear for REARM_DISTANCE_M and REARM_TIME_S, then out again: a new entry
    steps = int(max(REARM_DISTANCE_M / 1.0, REARM_TIME_S / DT)) + 2
    for k in range(steps):
        at(own, 19.0 + k, False)
    at(other, length - 20.0 - steps, True)
    assert det.totals["wrong_lane"] == 2


def test_wrong_lane_across_three_junctions_is_one_event():
    """On the opposite lane all the way along a route through three junctions: one entry."""
    ep = _three_junction_episode()
    det = _detector()
    width = NET.lane(ep.start_lane).width
    drive = list(_route_drive(ep.route, ep.start_lane, ep.start_pos + 5.0, 10.0, left_offset=width))
    assert _junction_passes([f for f, _, _ in drive]) == 3
    for frame, _, t in drive:
        _update(det, frame, t=t)
    assert det.totals["wrong_lane"] == 1 and det.totals["off_road"] == 0


def test_off_road_far_from_any_lane():
    det = _detector()
    lo = min(l.shape[:, 0].min() for l in NET.lanes.values())
    lo_y = min(l.shape[:, 1].min() for l in NET.lanes.values())
    ev = _update(det, EgoFrame(np.array([lo - 50.0, lo_y - 50.0]), 0.0, 4.5, 1.8))
    assert ev.off_road == 1 and ev.wrong_lane == 0


def test_off_road_beside_a_route_through_junctions_is_one_event():
    """5 m right of the route's lanes (on the kerb, through the corners of the junctions, past red
    lights): one excursion, and no red light, as the car never crosses its lane's stop line."""
    ep = _three_junction_episode()
    det = _detector()
    drive = list(_route_drive(ep.route, ep.start_lane, ep.start_pos + 5.0, 15.0, left_offset=-5.0, signal="r"))
    assert _junction_passes([f for f, _, _ in drive]) >= 2  # through junction corners, where the state is held
    for frame, _, t in drive:
        _update(det, frame, t=t)
    assert det.totals["off_road"] == 1 and det.totals["red_light"] == 0 and det.totals["wrong_lane"] == 0


def test_edge_jitter_is_one_off_road_event():
    """A car swerving across the road edge every other step (0.1 s): one entry, not one per swerve."""
    edge, _ = _two_way_edge()
    lane = NET.edge_lanes[edge][0]
    det = _detector()
    for k in range(40):
        xy, yaw = _lane_pose(lane, 10.0 + k)
        side = np.array([np.sin(yaw), -np.cos(yaw)])  # to the right
        _update(det, EgoFrame(xy + side * (4.0 if k % 2 else 0.0), yaw, 4.5, 1.8), t=k * DT)
    assert det.totals["off_road"] == 1


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


def _run_to_line(signal, speed, lateral=0.0, lane_change_to=None):
    """Drive the signalised lane's centre (shifted ``lateral`` [m] left) at ``speed`` [m/s] from 60 m
    before its stop line to 30 m past it; returns the detector's red-light count."""
    link = _signalised_link()
    lane = NET.lane(link.from_lane)
    line = _stop_line(lane.id, link.to_edge, signal)
    left = np.array([-line.direction[1], line.direction[0]])
    det = _detector()
    for k, s in enumerate(np.arange(-60.0, 30.0, speed * DT)):
        front = lane.shape[-1] + s * line.direction + lateral * left
        xy = front - 2.25 * line.direction
        _update(det, EgoFrame(xy, float(np.arctan2(line.direction[1], line.direction[0])), 4.5, 1.8, line, lane.edge), t=k * DT)
    return det.totals["red_light"]


@pytest.mark.parametrize("speed", [5.0, 15.0, 40.0, 120.0])
def test_red_crossing_is_one_event_at_any_speed(speed):
    """4 m per 0.1 s step at 40 m/s: no sample near the line, still one crossing."""
    assert _run_to_line("r", speed) == 1


def test_green_and_yellow_crossings_and_passing_beside_the_line_are_not_red():
    assert _run_to_line("G", 40.0) == 0
    assert _run_to_line("y", 10.0) == 0
    assert _run_to_line("r", 10.0, lateral=3.0) == 0  # beside the lane (on the opposite lane)
    assert _run_to_line("r", 10.0, lateral=12.0) == 0  # off the road


def test_backing_over_the_line_and_stopping_on_it_count_once():
    link = _signalised_link()
    lane = NET.lane(link.from_lane)
    line = _stop_line(lane.id, link.to_edge, "r")
    yaw = float(np.arctan2(line.direction[1], line.direction[0]))
    det = _detector()
    for k, s in enumerate([-5.0, -1.0, -0.1, 0.0, 0.0, 0.5, -0.5, 0.5, 5.0]):  # stops on the line, rolls back, goes
        front = lane.shape[-1] + s * line.direction
        _update(det, EgoFrame(front - 2.25 * line.direction, yaw, 4.5, 1.8, line, lane.edge), t=k * DT)
    assert det.totals["red_light"] == 1  # crossed forwards twice, at 0.0 and again at 0.5: one approach


def test_stop_line_follows_the_lane_not_a_light_ahead():
    """A line the car no longer follows after a lane change is still judged for the step it was
    followed; a line the car never follows is never judged."""
    link = _signalised_link()
    lane = NET.lane(link.from_lane)
    line = _stop_line(lane.id, link.to_edge, "r")
    yaw = float(np.arctan2(line.direction[1], line.direction[0]))
    det = _detector()
    front = lane.shape[-1] - 1.0 * line.direction
    _update(det, EgoFrame(front - 2.25 * line.direction, yaw, 4.5, 1.8, line, lane.edge), t=0.0)
    front = front + 3.0 * line.direction
    ev = _update(det, EgoFrame(front - 2.25 * line.direction, yaw, 4.5, 1.8, None, ""), t=0.1)
    assert ev.red_light == 1
    det = _detector()
    for k, s in enumerate([-2.0, 2.0]):  # same move, no followed signalised line
        front = lane.shape[-1] + s * line.direction
        _update(det, EgoFrame(front - 2.25 * line.direction, yaw, 4.5, 1.8, None, lane.edge), t=k * DT)
    assert det.totals["red_light"] == 0


def test_stop_line_geometry():
    link = _signalised_link()
    lane = NET.lane(link.from_lane)
    ends, direction, tls, index = LOCATOR.stop_line(lane.id, link.to_edge)
    assert (tls, index) == (link.tls, link.link_index)
    assert np.hypot(*(ends[1] - ends[0])) == pytest.approx(lane.width)
    assert ends.mean(axis=0) == pytest.approx(lane.shape[-1])
    assert (ends[1] - ends[0]) @ direction == pytest.approx(0.0, abs=1e-9)
    span = ends[1] - ends[0]
    assert direction[0] * span[1] - direction[1] * span[0] > 0  # ends[1] is the left end
    assert LOCATOR.stop_line(":internal", None) is None


def test_crosses_line_segment_test():
    ends, direction = np.array([[0.0, -1.0], [0.0, 1.0]]), np.array([1.0, 0.0])
    assert crosses_line(np.array([-5.0, 0.0]), np.array([50.0, 0.5]), ends, direction)
    assert crosses_line(np.array([-0.1, 1.0]), np.array([0.0, 1.0]), ends, direction)  # onto the end point
    assert not crosses_line(np.array([0.0, 0.0]), np.array([1.0, 0.0]), ends, direction)  # already on it
    assert not crosses_line(np.array([1.0, 0.0]), np.array([-1.0, 0.0]), ends, direction)  # backwards
    assert not crosses_line(np.array([-1.0, 1.5]), np.array([1.0, 1.5]), ends, direction)  # beside it
    assert not crosses_line(np.array([-1.0, 0.0]), np.array([-0.5, 5.0]), ends, direction)  # short of it


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


def test_segment_grid_finds_exactly_what_the_full_scan_finds():
    """The lane lookup's spatial index: the candidates it returns, filtered by the boxes, are the boxes
    that a scan over every segment of the map finds, in the same order (so the chosen lane is too)."""
    rng = np.random.default_rng(0)
    grid = LOCATOR._grid
    lo_all, hi_all = LOCATOR.lo, LOCATOR.hi
    span_lo, span_hi = lo_all.min(0) - 30.0, hi_all.max(0) + 30.0
    found = 0
    for _ in range(400):
        centre = rng.uniform(span_lo, span_hi)
        half = rng.uniform(0.0, 25.0, 2)
        q_lo, q_hi = centre - half, centre + half
        full = np.nonzero((hi_all >= q_lo).all(1) & (lo_all <= q_hi).all(1))[0]
        cand = grid.query(q_lo, q_hi)
        assert (np.diff(cand) > 0).all()
        np.testing.assert_array_equal(cand[(hi_all[cand] >= q_lo).all(1) & (lo_all[cand] <= q_hi).all(1)], full)
        found += len(full) > 0
    assert found > 100


def test_lane_lookup_agrees_with_a_scan_of_every_segment():
    rng = np.random.default_rng(1)
    lanes = list(NET.lanes.values())
    for _ in range(200):
        lane = lanes[rng.integers(len(lanes))]
        xy = lane.shape[rng.integers(len(lane.shape))] + rng.normal(0.0, 3.0, 2)
        points = footprint_points(xy, rng.uniform(-np.pi, np.pi), 4.6, 1.9)
        got = LOCATOR.locate(points)
        rel = points[:, None, :] - LOCATOR.a[None]
        t = np.clip(np.einsum("pmk,mk->pm", rel, LOCATOR.unit), 0.0, LOCATOR.seg_len)
        dist = np.hypot(*(rel - t[..., None] * LOCATOR.unit[None]).transpose(2, 0, 1))
        covered = dist <= LOCATOR.half_width[None]
        normal = LOCATOR.lane_index >= 0
        dist = np.where(covered & normal[None], dist, np.inf)
        best = np.argmin(dist, axis=1)
        expect = np.where(np.isfinite(dist.min(axis=1)), LOCATOR.lane_index[best], -1)
        np.testing.assert_array_equal(got[0], expect)
        on_junction_lane = (covered & ~normal[None]).any(axis=1)
        in_polygon = np.zeros(len(points), dtype=bool)
        for shape in LOCATOR.junctions:
            in_polygon |= points_in_polygon(points, shape)
        np.testing.assert_array_equal(got[2], in_polygon | (on_junction_lane & (expect < 0)))


@pytest.mark.parametrize("town", ["Town01", "Town03", "Town05"])
def test_compiled_lane_lookup_equals_its_numpy_form(town):
    """Lanes, directions and junction flags of footprints on and beside every kind of lane, with and
    without a preferred edge (the ego's own, another, none): equal arrays."""
    net = road_network(town)
    locator = LaneLocator(net)
    rng = np.random.default_rng(2)
    lanes = list(net.lanes.values())
    edges = sorted({lane.edge for lane in lanes})
    judged = in_junction = 0
    for k in range(600):
        lane = lanes[rng.integers(len(lanes))]
        xy = lane.shape[rng.integers(len(lane.shape))] + rng.normal(0.0, 4.0, 2)
        points = footprint_points(xy, rng.uniform(-np.pi, np.pi), 4.6, 1.9)
        prefer = ("", lane.edge, edges[rng.integers(len(edges))])[k % 3]
        got, expect = locator.locate(points, prefer), locator.locate_reference(points, prefer)
        for a, b in zip(got, expect):
            np.testing.assert_array_equal(a, b)
        judged += (got[0] >= 0).any()
        in_junction += got[2].any()
    assert judged > 300 and in_junction > 100
