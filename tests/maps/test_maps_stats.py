"""The shipped towns match the spec table (CARLA Town01-Town05 statistics, +-30 %)."""

from __future__ import annotations

import pytest

from hbmp_bench.maps import TOWNS, map_stats
from hbmp_bench.maps.stats import format_stats

# The spec: directed road length (m), {vehicle lanes per edge: edges}, TLS / priority
# junctions, extent (x, y) in m. Length, junction counts and extent must lie within
# +-30 %; lane counts must be the same set with shares within 15 percentage points.
TARGETS = {
    "Town01": dict(length=4960, lanes={1: 1}, tls=16, prio=4, extent=(394, 329)),
    "Town02": dict(length=2110, lanes={1: 1}, tls=14, prio=2, extent=(197, 197)),
    "Town03": dict(length=4860, lanes={1: 14, 2: 88, 3: 15}, tls=11, prio=31,
                   extent=(394, 403)),
    "Town04": dict(length=9240, lanes={1: 65, 2: 2, 4: 32}, tls=12, prio=21,
                   extent=(905, 808)),
    "Town05": dict(length=7700, lanes={2: 82, 3: 24}, tls=15, prio=21, extent=(473, 399)),
}
TOL = 0.30
SHARE_TOL = 0.15


def _within(value: float, target: float) -> bool:
    return (1 - TOL) * target <= value <= (1 + TOL) * target


def test_towns_listed():
    assert TOWNS == ("Town01", "Town02", "Town03", "Town04", "Town05")
    assert set(TARGETS) == set(TOWNS)


@pytest.mark.parametrize("town", TOWNS)
def test_stats_within_bounds(town):
    s, t = map_stats(town), TARGETS[town]
    assert _within(s["directed_road_length_m"], t["length"]), s
    assert _within(s["tls_junctions"], t["tls"]), s
    assert _within(s["priority_junctions"], t["prio"]), s
    for got, want in zip(s["extent_m"], t["extent"]):
        assert _within(got, want), s


@pytest.mark.parametrize("town", TOWNS)
def test_lane_counts(town):
    s, t = map_stats(town), TARGETS[town]
    got = {int(k): v for k, v in s["lanes_per_edge"].items()}
    assert set(got) == set(t["lanes"])
    assert sum(got.values()) == s["drivable_edges"]
    n_got, n_want = sum(got.values()), sum(t["lanes"].values())
    for lanes, count in t["lanes"].items():
        assert abs(got[lanes] / n_got - count / n_want) <= SHARE_TOL, (lanes, got)


@pytest.mark.parametrize("town", TOWNS)
def test_sidewalks_and_crossings(town):
    s = map_stats(town)
    assert s["has_sidewalks"]
    assert s["crossings"] > 0


@pytest.mark.parametrize("town", TOWNS)
def test_vehicle_edges_allow_passenger_and_speeds(nets, town):
    for edge in nets[town].getEdges(withInternal=False):
        vehicle = [ln for ln in edge.getLanes() if ln.getPermissions() != {"pedestrian"}]
        if not vehicle:
            continue  # a pure footpath
        assert all(ln.allows("passenger") for ln in vehicle), edge.getID()
        if town == "Town04" and len(vehicle) == 4:   # the highway
            assert edge.getSpeed() == pytest.approx(25.0), edge.getID()
        elif town == "Town04":                        # ramps and town streets
            assert edge.getSpeed() <= 16.67 + 1e-6, edge.getID()
        else:
            assert edge.getSpeed() == pytest.approx(13.89), edge.getID()


def _legs(node) -> int:
    """Number of neighbouring nodes reached by vehicle edges (in or out)."""
    others = set()
    for e in node.getIncoming() + node.getOutgoing():
        if e.getFunction() == "" and e.allows("passenger"):
            others.add(e.getFromNode().getID() if e.getToNode() is node
                       else e.getToNode().getID())
    return len(others)


def _junctions(net):
    return [n for n in net.getNodes() if n.getType() not in ("internal", "dead_end")]


@pytest.mark.parametrize("town", ["Town01", "Town02"])
def test_t_junctions_only(nets, town):
    assert {_legs(n) for n in _junctions(nets[town])} == {3}


def test_town03_roundabout_and_five_leg_tls(nets):
    net = nets["Town03"]
    assert map_stats("Town03")["roundabouts"] >= 1
    assert len(net.getRoundabouts()) >= 1
    five = [n for n in _junctions(net) if n.getType() == "traffic_light" and _legs(n) == 5]
    assert five


def test_town05_signalised_crosses(nets):
    crosses = [n for n in _junctions(nets["Town05"]) if _legs(n) == 4]
    assert len(crosses) >= 12
    assert all(n.getType() == "traffic_light" for n in crosses)


def test_town04_highway_loop(nets):
    net = nets["Town04"]
    highway = [e for e in net.getEdges(withInternal=False)
               if e.allows("passenger") and e.getLaneNumber() == 4]
    assert len(highway) >= 16
    assert all(e.getSpeed() == pytest.approx(25.0) for e in highway)
    # the highway edges alone form two loops (one per carriageway)
    ids = {e.getID() for e in highway}
    nxt = {e.getID(): [o.getID() for o in e.getOutgoing() if o.getID() in ids] for e in highway}
    assert all(len(v) == 1 for v in nxt.values())


def test_format_stats_sets_maps_side_by_side():
    stats = {"Town02": map_stats("Town02"), "Town01": map_stats("Town01")}
    lines = format_stats(stats).splitlines()
    assert lines[0].split() == ["Town02", "Town01"]
    rows = {line.split()[0]: line.split()[1:] for line in lines[1:]}
    assert set(rows) == set(stats["Town02"])
    a, b = stats["Town02"]["directed_road_length_m"], stats["Town01"]["directed_road_length_m"]
    assert rows["directed_road_length_m"] == [f"{a:g}", f"{b:g}", f"({100 * (b - a) / a:+.1f}%)"]
    w, h = stats["Town01"]["extent_m"]
    assert " ".join(rows["extent_m"]).endswith(f"{w:g} x {h:g}")
    mean = stats["Town01"]["lanes_per_edge_mean"]
    assert mean == pytest.approx(stats["Town01"]["driving_lane_length_m"] / b, abs=1e-3)
