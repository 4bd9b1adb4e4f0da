"""``update_all`` (every vehicle's detectors in one pass) against one ``update`` per vehicle, and
``LaneLocator.locate_all`` against ``locate``, on Town01's geometry (no SUMO): equal bit for bit."""

import dataclasses

import numpy as np

from hbmp_bench.metrics import EgoFrame, InfractionDetector, LaneLocator
from hbmp_bench.metrics.detectors import StopLine, update_all
from hbmp_bench.metrics.geometry import footprint_points
from hbmp_bench.scenarios import road_network

NET = road_network("Town01")
LOCATOR = LaneLocator(NET)


def _signalised_lanes(count):
    out = []
    for conns in NET.connections.values():
        for c in conns:
            if c.tls and LOCATOR.stop_line(c.from_lane, c.to_edge) is not None:
                out.append((c.from_lane, c.to_edge))
    return out[:count]


def _scene(rng, lanes, step):
    """N vehicles driving towards the stop lines of ``lanes`` (some crossing them at red), jittered
    off their lanes and turned (wrong lane, off-road), two of them and a pedestrian on top of others
    (contacts); and the snapshot: every vehicle plus a few other actors."""
    frames, xy, yaw = [], [], []
    for k, (lane, nxt) in enumerate(lanes):
        length = NET.lane(lane).length
        pos = min(length - 6.0 + 0.9 * step, length + 8.0)
        p = NET.position(lane, min(pos, length - 0.01))
        ahead = NET.position(lane, min(pos, length - 0.01) - 0.5)
        heading = float(np.arctan2(*(p - ahead)[::-1]))
        if k % 3 == 1:
            heading += np.pi * (step // 5 % 2)  # turned round every 5 steps: wrong lane
        offset = rng.normal(0.0, 1.5 if k % 3 == 2 else 0.2, 2)  # some drift off the road
        centre = p + offset
        ends, direction, _, _ = LOCATOR.stop_line(lane, nxt)
        signal = "r" if k % 2 == 0 else "G"
        frames.append(EgoFrame(centre, heading, 4.6 if k == 0 else 4.5, 1.9 if k == 0 else 1.8,
                               StopLine(lane, ends, direction, signal), NET.lane(lane).edge))
        xy.append(centre)
        yaw.append(heading)
    ids = [f"v{k}" for k in range(len(frames))]
    # others: one on top of v0, one touching v1, a pedestrian at v2, far ones
    extra = [("bgA", frames[0].xy + [1.0, 0.3], yaw[0], False), ("bgB", frames[1].xy + [3.0, 1.0], 0.3, False),
             ("ped0", frames[2].xy + [0.5, -0.4], 0.0, True), ("bgC", np.array([1e4, 1e4]), 0.0, False)]
    if step % 4 == 3:
        extra = extra[1:]  # contact with bgA ends, and starts again
    ids += [e[0] for e in extra]
    xy = np.array(xy + [e[1] for e in extra])
    yaw = np.array(yaw + [e[2] for e in extra])
    ped = np.array([False] * len(frames) + [e[3] for e in extra])
    length = np.where(ped, 0.6, 4.5)
    length[0] = 4.6
    width = np.where(ped, 0.6, 1.8)
    width[0] = 1.9
    return frames, tuple(ids), xy, yaw, length, width, ped


def _detectors(n):
    return [InfractionDetector(LOCATOR, goal_xy=np.array([1e6, 1e6]), success_radius_m=2.0, timeout_s=2.5)
            for _ in range(n)]


def test_update_all_equals_update_per_vehicle():
    lanes = _signalised_lanes(9)
    assert len(lanes) == 9
    batched, single = _detectors(9), _detectors(9)
    rng = np.random.default_rng(0)
    seen = dict.fromkeys(["collision_vehicle", "collision_pedestrian", "wrong_lane", "off_road", "red_light"], 0)
    for step in range(30):
        frames, ids, xy, yaw, length, width, ped = _scene(rng, lanes, step)
        visible = np.ones((len(frames), len(ids)), dtype=bool)
        for k in range(len(frames)):
            visible[k, k] = False
        visible[4, 0] = False  # a vehicle on another level
        time_s = 0.1 * step
        events = update_all(batched, frames, ids, xy, yaw, length, width, ped, visible, time_s)
        for k, (det, frame) in enumerate(zip(single, frames)):
            keep = visible[k]
            ev = det.update(frame, tuple(i for i, v in zip(ids, keep) if v), xy[keep], yaw[keep], length[keep],
                            width[keep], ped[keep], time_s)
            assert ev == events[k], (step, k)
            for kind in seen:
                seen[kind] += getattr(ev, kind)
    for a, b in zip(batched, single):
        for f in dataclasses.fields(a):
            x, y = getattr(a, f.name), getattr(b, f.name)
            if isinstance(x, np.ndarray):
                assert np.array_equal(x, y)
            elif f.name != "locator":
                assert x == y, f.name
    assert all(seen.values()), seen  # every kind happened: the comparison covers each


def test_locate_all_equals_locate():
    rng = np.random.default_rng(1)
    lanes = list(NET.lanes)
    points, edges = [], []
    for k in range(40):
        lane = lanes[int(rng.integers(len(lanes)))]
        xy = NET.position(lane, float(rng.uniform(0.0, NET.lane(lane).length))) + rng.normal(0.0, 3.0, 2)
        points.append(footprint_points(xy, float(rng.uniform(-np.pi, np.pi)), 4.5 + 10.0 * (k % 5 == 0), 1.8))
        edges.append(NET.lane(lane).edge if k % 2 else "")
    lane, direction, junction = LOCATOR.locate_all(np.stack(points), edges)
    for k, (p, e) in enumerate(zip(points, edges)):
        one = LOCATOR.locate(p, prefer_edge=e)
        assert np.array_equal(lane[k], one[0]) and np.array_equal(direction[k], one[1])
        assert np.array_equal(junction[k], one[2])
