"""Conflicting links through a junction (crossings, merges, close passes), from the junction lanes' geometry."""

import numpy as np
import pytest

from hbmp_bench.maps.roadnet import CONFLICT_WIDTH_M
from hbmp_bench.scenarios import road_network


def _heading(net, link, at_start: bool) -> np.ndarray:
    shape = net.link_shape(link)
    d = shape[1] - shape[0] if at_start else shape[-1] - shape[-2]
    return d / np.linalg.norm(d)


@pytest.mark.parametrize("town", ["Town01", "Town03"])
def test_a_left_turn_conflicts_with_the_oncoming_straight(town):
    net = road_network(town)
    found = 0
    for conns in net.connections.values():
        for link in conns:
            if link.direction != "l" or not link.tls:
                continue
            entry = _heading(net, link, at_start=True)
            oncoming = [c for c in net.connections.values() for c in c
                        if c.direction == "s" and net.edge_from_to[c.from_edge][1] == net.edge_from_to[link.from_edge][1]
                        and float(_heading(net, c, at_start=True) @ entry) < -0.9]
            if not oncoming:
                continue
            foes = {c.foe for c in net.link_conflicts(link)}
            assert all(c in foes for c in oncoming), link
            found += 1
    assert found > 0


def test_conflicts_are_symmetric_and_inside_both_links():
    net = road_network("Town01")
    checked = 0
    for conns in list(net.connections.values())[:40]:
        for link in conns:
            length = len(net.link_shape(link)) and float(np.hypot(*np.diff(net.link_shape(link), axis=0).T).sum())
            for c in net.link_conflicts(link):
                assert c.foe.from_lane != link.from_lane
                assert 0.0 <= c.at_m <= c.clear_m <= length + 1e-6
                back = [b for b in net.link_conflicts(c.foe) if b.foe == link]
                assert len(back) == 1  # the foe conflicts with the link too ...
                assert back[0].foe_at_m == pytest.approx(c.at_m, abs=1.0)  # ... at the same place
                assert back[0].at_m == pytest.approx(c.foe_at_m, abs=1.0)
                checked += 1
    assert checked > 20


def test_conflicting_links_come_close():
    net = road_network("Town01")
    for conns in list(net.connections.values())[:40]:
        for link in conns:
            shape = net.link_shape(link)
            for c in net.link_conflicts(link):
                foe = net.link_shape(c.foe)
                gap = np.min(np.hypot(*(shape[:, None, :] - foe[None, :, :]).transpose(2, 0, 1)))
                assert gap < CONFLICT_WIDTH_M + 5.0  # vertices are a few metres apart at most


def test_polyline_samples_are_the_points_at_their_arc_lengths():
    """The conflict and crossing zones sample link shapes in one vectorised pass: the same points as
    ``point_along`` at each arc length, zero-length segments (duplicated shape points) included."""
    from hbmp_bench.maps.roadnet import _sample_polyline, point_along

    rng = np.random.default_rng(0)
    for k in range(300):
        shape = np.cumsum(rng.normal(size=(int(rng.integers(2, 8)), 2)) * rng.uniform(0.1, 5.0), axis=0)
        if k % 3 == 0:
            shape = np.insert(shape, 1, shape[1], axis=0)
        s, points = _sample_polyline(shape, 0.5)
        assert s[0] == 0.0 and np.all(np.diff(s) > 0) and np.diff(s)[:-1] == pytest.approx(0.5)
        np.testing.assert_allclose(points, [point_along(shape, x) for x in s], atol=1e-9)
