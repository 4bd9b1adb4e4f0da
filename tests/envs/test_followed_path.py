"""The centreline the motion planner tracks (``followed_path`` as the continuous drivers build it)."""

import numpy as np
import pytest

from hbmp_bench.envs.observation import followed_path
from hbmp_bench.maps.netconvert import run_netconvert
from hbmp_bench.maps.roadnet import RoadNetwork, project_on_polyline
from hbmp_bench.scenarios import road_network


@pytest.mark.parametrize("town", ["Town01", "Town02"])
def test_rounded_centrelines_have_no_kinks_at_lane_joints(town):
    """Every lane followed onto each edge it leads to: the rounded centreline bends no sharper than
    the towns' tightest corners (R ~ 4 m), where the lanes meet the junction lanes included."""
    net = road_network(town)
    worst = 0.0
    for lane in sorted(net.lanes):
        for _, edge in net.lane_next.get(lane, ()):
            path = followed_path(net, lane, (edge,), 10.0, 30.0, max_spacing=1.0, round_corners=3)
            worst = max(worst, float(np.abs(path.kappa).max()))
    assert 0.1 < worst < 0.3


@pytest.fixture(scope="module")
def fan_net(tmp_path_factory):
    """A lane that fans out: AB (one lane) links to both lanes of BC; at C only BC_1 turns left onto
    CD, only BC_0 goes straight onto CE (plain XML through netconvert)."""
    d = tmp_path_factory.mktemp("fan")
    (d / "f.nod.xml").write_text('<nodes><node id="A" x="0" y="0"/><node id="B" x="100" y="0"/>'
                                 '<node id="C" x="160" y="0"/><node id="D" x="160" y="100"/>'
                                 '<node id="E" x="260" y="0"/></nodes>')
    edges = "".join(f'<edge id="{e}" from="{e[0]}" to="{e[1]}" numLanes="{n}" speed="13.89"/>'
                    for e, n in (("AB", 1), ("BC", 2), ("CD", 1), ("CE", 1)))
    (d / "f.edg.xml").write_text(f"<edges>{edges}</edges>")
    links = "".join(f'<connection from="{a}" to="{b}" fromLane="{i}" toLane="{j}"/>'
                    for a, b, i, j in (("AB", "BC", 0, 0), ("AB", "BC", 0, 1), ("BC", "CE", 0, 0), ("BC", "CD", 1, 0)))
    (d / "f.con.xml").write_text(f"<connections>{links}</connections>")
    run_netconvert(["-n", "f.nod.xml", "-e", "f.edg.xml", "-x", "f.con.xml", "-o", "f.net.xml",
                    "--no-turnarounds", "true"], cwd=d)
    return RoadNetwork.from_sumo(d / "f.net.xml")


def _end_lane(net, path) -> str:
    """The lane of ``net`` whose centreline the end of ``path`` lies on."""
    end = path.xy[-1]
    return min(net.lanes, key=lambda ln: project_on_polyline(net.lane(ln).shape, end)[1])


@pytest.mark.parametrize("goal, lane_after_fan", [("CD_0", "BC_1"), ("CE_0", "BC_0")])
def test_followed_path_takes_the_link_into_the_route_lanes(fan_net, goal, lane_after_fan):
    """From AB_0 the first link leads into BC_0; the followed path takes the link into the lane of BC
    from which the route goes on to the goal (the route's lanes there), for the planner's rounded
    centreline and M_t's, and goes on through C onto the goal edge."""
    net = fan_net
    assert net.lane_next["AB_0"][0][0] == ":B_0_0" and net.follow("AB_0", "BC") == ":B_0_0"  # first: into BC_0
    route = ("AB", "BC", net.lane(goal).edge)
    into = net.route_lanes(route, goal, 50.0)[1:]
    assert into[0] == {lane_after_fan}
    for kwargs in ({}, {"max_spacing": 1.0, "round_corners": 3}):
        short = followed_path(net, "AB_0", route[1:], 10.0, 20.0, into=into, **kwargs)
        assert _end_lane(net, short) == lane_after_fan
        long = followed_path(net, "AB_0", route[1:], 10.0, 150.0, into=into, **kwargs)
        assert _end_lane(net, long) == goal


def test_followed_path_is_unchanged_where_one_link_leads_on(fan_net):
    """Route lanes change nothing where a lane has one link onto the next edge, nor without them."""
    net = fan_net
    for lane, edges, into in (("BC_1", ("CD",), ({"CD_0"},)), ("BC_0", ("CE",), ({"CE_0"},)),
                              ("BC_1", ("CD",), ({"CE_0"},))):
        into = tuple(frozenset(s) for s in into)
        assert net.follow(lane, edges[0], into[0]) == net.follow(lane, edges[0])
        np.testing.assert_array_equal(followed_path(net, lane, edges, 10.0, 60.0, into=into).xy,
                                      followed_path(net, lane, edges, 10.0, 60.0).xy)
    np.testing.assert_array_equal(followed_path(net, "AB_0", ("BC", "CD"), 10.0, 150.0).xy,
                                  followed_path(net, "AB_0", ("BC", "CD"), 10.0, 150.0, into=()).xy)
    assert _end_lane(net, followed_path(net, "AB_0", ("BC",), 10.0, 20.0)) == "BC_0"  # no route lanes: the first
