"""Route lengths and route progress on the lane graph: the length a car drives, junction lanes included."""

import numpy as np
import pytest
import sumolib

from hbmp_bench.maps import net_path
from hbmp_bench.maps.netconvert import run_netconvert
from hbmp_bench.maps.roadnet import LANE_CHANGE_CUTOFF_M, RoadNetwork, point_along, project_on_polyline
from hbmp_bench.scenarios import road_network, suite_episodes


@pytest.mark.parametrize("town", ["Town01", "Town03"])
def test_route_length_agrees_with_sumos_router_including_junctions(town):
    """sumolib's shortest path over normal and internal edges costs the SUMO length of every lane
    driven. Where those lengths are the drawn ones, our length is SUMO's; elsewhere (curved
    multi-lane edges share one SUMO length) ours follows the drawn lanes. Leaving the junctions out,
    the old measure, was 20-60% short on these routes."""
    ref_net = sumolib.net.readNet(str(net_path(town)), withInternal=True)
    net = road_network(town)
    exact = 0
    for ep in suite_episodes("corl2017", town, "Straight"):
        edges, cost = ref_net.getShortestPath(ref_net.getEdge(ep.route[0]), ref_net.getEdge(ep.route[-1]),
                                              withInternal=True, vClass="passenger")
        assert tuple(e.getID() for e in edges if e.getFunction() != "internal") == ep.route
        reference = cost - ep.start_pos - (ref_net.getEdge(ep.route[-1]).getLength() - ep.goal_pos)
        path = net.route_path(ep.route, ep.start_lane, ep.goal_lane)
        if all(net.lane(ln).shape_length == pytest.approx(net.lane(ln).length, rel=0.002) for ln in path.lanes):
            assert ep.route_length_m == pytest.approx(reference, abs=0.05 + 0.002 * reference)
            exact += 1
        junctions = sum(net.lane(ln).shape_length for ln in path.lanes if ln in net.internal_lanes)
        edges_only = sum(net.edge_length[e] for e in ep.route) - ep.start_pos - net.edge_length[ep.route[-1]] + ep.goal_pos
        assert junctions > 0.0
        assert ep.route_length_m == pytest.approx(edges_only + junctions, rel=0.1)
    assert exact >= 15


def test_route_path_is_a_connected_lane_sequence():
    net = road_network("Town03")
    for ep in suite_episodes("corl2017", "Town03", "OneTurn")[:10]:
        path = net.route_path(ep.route, ep.start_lane, ep.goal_lane)
        assert net.lane(path.lanes[0]).edge == ep.route[0] and path.lanes[-1] == ep.goal_lane
        assert [net.lane(ln).edge for ln in path.lanes if ln in net.lanes] == list(ep.route)
        for a, b in zip(path.lanes[:-1], path.lanes[1:]):
            steps = {step for step, _ in net.lane_next[a]}
            # b follows a, or a leads onto b's edge and the car changes lanes on it
            assert b in steps or net.lane(b).edge in {net.lane(step).edge for step in steps}, (a, b)
        assert len(path.junctions) == len(ep.route) - 1 and all(path.junctions)
        lengths = [net.lane(ln).shape_length for ln in path.lanes]
        assert path.offsets[-1] == pytest.approx(sum(lengths))
        assert np.all(path.edge_start[1:] > path.edge_end[:-1])  # a junction lies between two edges


def test_position_is_a_sumo_lane_position_scaled_onto_the_shape():
    """SUMO maps a lane position onto the drawn shape scaled by shape length / length; a lane of
    Town04 whose shape is 8 m shorter than its SUMO length shows the difference."""
    net = road_network("Town04")
    lane = net.lane("Kin_E_Din_S_0")
    assert lane.length - lane.shape_length > 5.0
    for pos in (0.0, 100.0, lane.length / 2, lane.length):
        arc, off = project_on_polyline(lane.shape, net.position(lane.id, pos))
        assert off == pytest.approx(0.0, abs=1e-6)
        assert arc == pytest.approx(pos * lane.shape_length / lane.length, abs=1e-6)


def test_single_edge_route_length_is_the_scaled_gap():
    net = road_network("Town01")
    edge = net.drivable_edges[0]
    lane = net.lane(net.rightmost_lane(edge))
    assert net.route_length((edge,), 10.0, 40.0) == pytest.approx(30.0 * lane.shape_length / lane.length)


def test_junction_position_runs_through_the_junction_without_jumps():
    net = road_network("Town03")
    ep = suite_episodes("corl2017", "Town03", "OneTurn")[0]
    path = net.route_path(ep.route, ep.start_lane, ep.goal_lane)
    k = int(np.argmax([len(j) for j in path.junctions]))
    before = path.position(k, net.edge_length[path.route[k]])
    after = path.position(k + 1, 0.0)
    assert before == pytest.approx(path.edge_end[k]) and after == pytest.approx(path.edge_start[k + 1])
    positions = []
    for lane in path.junctions[k]:
        for s in np.linspace(0.0, net.lane(lane.id).shape_length, 7):
            positions.append(path.junction_position(k, point_along(lane.shape, s) + np.array([0.4, -0.3])))
    steps = np.diff([before, *positions, after])
    assert np.all(steps >= -0.6) and np.max(steps) < 0.5 * (after - before)
    assert positions[0] == pytest.approx(before, abs=0.6) and positions[-1] == pytest.approx(after, abs=0.6)


@pytest.mark.parametrize("town", ["Town03", "Town05"])
def test_routes_are_shortest_by_length_driven(town):
    """Routes are chosen by the length driven, junction lanes included (sumolib's router over
    internal edges agrees where its route is drivable); choosing by edge lengths alone took detours of up
    to 8.5 % here."""
    ref_net = sumolib.net.readNet(str(net_path(town)), withInternal=True)
    net = road_network(town)
    episodes = suite_episodes("corl2017", town, "Navigation") + suite_episodes("corl2017", town, "OneTurn")
    for ep in episodes:
        edges, cost = ref_net.getShortestPath(ref_net.getEdge(ep.route[0]), ref_net.getEdge(ep.route[-1]),
                                              withInternal=True, vClass="passenger")
        reference = tuple(e.getID() for e in edges if e.getFunction() != "internal")
        if any(b not in net.successors(a) for a, b in zip(reference[:-1], reference[1:])):
            continue  # SUMO's router also takes links too sharp for a car (SHARPEST_TURN_RADIUS_M)
        if reference != ep.route:  # a tie or SUMO's shared length on a curved edge: never a real detour
            ours = net.route_length(ep.route, 0.0, net.edge_length[ep.route[-1]])
            theirs = net.route_length(reference, 0.0, net.edge_length[reference[-1]])
            assert ours <= theirs * 1.005, (ep.key, ours, theirs)


def test_shortest_trees_are_computed_once_read_only_and_pickle():
    """A reset draws background routes from shortest trees: each source's is computed once, shared read-only
    (a caller cannot corrupt the next one's), and a network still pickles (the copy computes its own)."""
    import pickle

    net = road_network("Town01")
    source = net.drivable_edges[0]
    dist, prev = net.shortest_tree(source)
    assert net.shortest_tree(source)[0] is dist
    with pytest.raises(TypeError):
        dist[source] = 1.0
    fresh = RoadNetwork.from_sumo(net_path("Town01"))._dijkstra(source)
    assert (dict(dist), dict(prev)) == fresh
    copy = pickle.loads(pickle.dumps(net))
    assert dict(copy.shortest_tree(source)[0]) == dict(dist)


def test_route_lanes_reach_a_goal_lane_that_leaves_no_room_to_change():
    """Town03's roundabout: ring segments of 12.5-16 m leave no room for a lane change, so from the
    ring's entry on only the lanes whose links land on the goal lane lead to it; before a long
    edge every linking lane does."""
    net = road_network("Town03")
    route = ("-AW_X90_235", "-I90_130_AW", "-X90_95_I90_130")
    goal = "-X90_95_I90_130_1"
    good = net.route_lanes(route, goal, goal_pos=8.57)
    assert good[-1] == {goal}
    assert good[1] == {"-I90_130_AW_1"} and good[0] == {"-AW_X90_235_1"}
    assert len(net.lanes_to(route[0], route[1])) == 2  # both lanes link on: the rule, not the map, narrows them
    # a goal far enough along the goal edge leaves room to change lanes there: one change takes
    # max(20 m, 3 s at the 13.9 m/s limit) by default, 20 m when changes take 1 s
    route = ("-X230_235_Pr235", "-I195_235_X230_235", "-AN_I195_235", "-X90_235_AN", "-I45_235_X90_235")
    assert net.route_lanes(route, "-I45_235_X90_235_1", goal_pos=25.0, change_s=1.0)[3] == set(net.lanes_to(route[3], route[4]))
    assert net.route_lanes(route, "-I45_235_X90_235_1", goal_pos=25.0)[3] == {"-X90_235_AN_1"}
    assert net.route_lanes(route, "-I45_235_X90_235_1", goal_pos=10.85, change_s=1.0)[3] == {"-X90_235_AN_1"}
    # the lanes a car drives (and so the route length) follow the same rule
    path = net.route_path(route, "-X230_235_Pr235_2", "-I45_235_X90_235_1", 10.85)
    assert "-X90_235_AN_1" in path.lanes and "-X90_235_AN_2" not in path.lanes


def test_route_lanes_cross_several_lanes_of_a_fast_road_in_time():
    """Town04's 4-lane motorway at 25 m/s: a lane change takes 75 m, so a goal on the rightmost lane
    96 m into its edge is reached from at most one lane away; the edge before must be left by
    the two rightmost lanes (each links straight on)."""
    net = road_network("Town04")
    route = ("Kout_W_Dout_S", "Dout_S_Mout_S")
    good = net.route_lanes(route, "Dout_S_Mout_S_0", goal_pos=96.18)
    assert good == (frozenset({"Kout_W_Dout_S_0", "Kout_W_Dout_S_1"}), frozenset({"Dout_S_Mout_S_0"}))
    assert len(net.lanes_to(*route)) == 4


def test_route_lanes_leave_room_for_every_lane_change_before_the_goal():
    """Town05 at 13.89 m/s: a lane change takes 41.7 m. A goal in the rightmost of three lanes 33 m
    into its edge leaves room for none (only the lane landing on the goal lane), 45 m for one,
    90 m for two (every lane)."""
    net = road_network("Town05")
    route = ("C4R1_C4R2", "-C3R2_C4R2", "-C2R2_C3R2", "-C1R2_C2R2")
    good = net.route_lanes(route, "-C1R2_C2R2_1", goal_pos=33.22)
    assert good[-1] == {"-C1R2_C2R2_1"}
    assert good[-2] == {"-C2R2_C3R2_1"}
    assert net.route_lanes(route, "-C1R2_C2R2_1", goal_pos=45.0)[-2] == {"-C2R2_C3R2_1", "-C2R2_C3R2_2"}
    assert net.route_lanes(route, "-C1R2_C2R2_1", goal_pos=90.0)[-2] == set(net.lanes_to(route[2], route[3]))


def test_sharpest_turn_radius_measures_arcs_and_ignores_straight_lines():
    from hbmp_bench.maps.roadnet import sharpest_turn_radius

    theta = np.linspace(0.0, np.pi / 2, 200)
    for radius in (4.0, 10.0, 30.0):
        arc = np.c_[radius * np.cos(theta), radius * np.sin(theta)]
        assert sharpest_turn_radius(arc) == pytest.approx(radius, rel=0.03)
    assert sharpest_turn_radius(np.array([[0.0, 0.0], [5.0, 0.0], [12.0, 0.0]])) == np.inf
    # a straight stretch, then a 1.5 m-radius half circle (4.7 m of arc, longer than the window): it decides
    half = np.linspace(0.0, np.pi, 200)[1:]
    hook = np.vstack([np.c_[np.linspace(-20.0, 0.0, 20), np.zeros(20)],
                      np.c_[1.5 * np.sin(half), 1.5 - 1.5 * np.cos(half)]])
    assert sharpest_turn_radius(hook) == pytest.approx(1.5, rel=0.1)


def test_routes_avoid_links_too_sharp_for_a_car_but_foes_keep_them():
    """Town04's ramp terminal turns 135 degrees within 13 m from the inner carriageway's exit onto the outer
    one's entry: no route takes it, while the link stays in ``connections`` (SUMO's cars still drive it, so
    it still counts as a foe and carries its light)."""
    from hbmp_bench.maps.roadnet import SHARPEST_TURN_RADIUS_M

    net = road_network("Town04")
    sharp = [c for c in net.connections["Din_E_R_E"] if c.to_edge == "R_E_Mout_E"]
    assert sharp and all(net.link_turn_radius(c) < SHARPEST_TURN_RADIUS_M for c in sharp)
    assert "R_E_Mout_E" not in net.successors("Din_E_R_E") and not net.links("Din_E_R_E", "R_E_Mout_E")
    assert "R_E_Min_E" in net.successors("Din_E_R_E")
    assert all(net.link_turn_radius(c) >= SHARPEST_TURN_RADIUS_M
               for conns in net.connections.values() for c in conns if c in net.links(c.from_edge, c.to_edge))


def test_start_lanes_reach_the_route_lanes():
    """Town03: the start edge ``-X90_95_I90_130`` is 12.5 m long and only its left lane turns onto
    ``X90_95_I125_95``: a start 6 m in can only be in that lane. ``AE_I230_200`` (16 m) leads onto another
    16 m edge whose left lane alone continues to ``-I195_235_X230_235``: no room for a change on either, so
    only the left lane of the start edge follows that route. On a long edge every lane qualifies."""
    net = road_network("Town03")
    route = ("-X90_95_I90_130", "X90_95_I125_95")
    assert set(net.reachable_start_lanes(route, 5.97, 8.0)) == {c.from_lane for c in net.links(*route)}
    route = ("AE_I230_200", "I230_200_X230_235", "-I195_235_X230_235", "-AN_I195_235")
    assert net.reachable_start_lanes(route, 7.65, 20.0) == ("AE_I230_200_2",)
    long_edge = max(net.edge_lanes, key=lambda e: net.edge_length[e] if len(net.edge_lanes[e]) > 1 else 0)
    nxt = net.successors(long_edge)[0]
    assert net.reachable_start_lanes((long_edge, nxt), 1.0, 10.0) == net.edge_lanes[long_edge]


def _split_then_turn_net(tmp_path) -> RoadNetwork:
    """A two-lane road (``long``, 100 m) split by a plain node from a short piece (``short``, 8 m) before a
    junction where only the left lane turns left (``left``) and only the right lane goes on (``on``)."""
    (tmp_path / "n.nod.xml").write_text(
        '<nodes><node id="a" x="0" y="0"/><node id="b" x="100" y="0"/><node id="c" x="108" y="0"/>'
        '<node id="d" x="208" y="0"/><node id="e" x="108" y="100"/></nodes>', encoding="utf-8")
    (tmp_path / "n.edg.xml").write_text(
        '<edges><edge id="long" from="a" to="b" numLanes="2" speed="13.89"/>'
        '<edge id="short" from="b" to="c" numLanes="2" speed="13.89"/>'
        '<edge id="left" from="c" to="e" numLanes="1" speed="13.89"/>'
        '<edge id="on" from="c" to="d" numLanes="1" speed="13.89"/></edges>', encoding="utf-8")
    (tmp_path / "n.con.xml").write_text(
        '<connections><connection from="long" to="short" fromLane="0" toLane="0"/>'
        '<connection from="long" to="short" fromLane="1" toLane="1"/>'
        '<connection from="short" to="left" fromLane="1" toLane="0"/>'
        '<connection from="short" to="on" fromLane="0" toLane="0"/></connections>', encoding="utf-8")
    run_netconvert(["-n", "n.nod.xml", "-e", "n.edg.xml", "-x", "n.con.xml", "-o", "n.net.xml"], cwd=tmp_path)
    return RoadNetwork.from_sumo(tmp_path / "n.net.xml")


def test_route_drivable_needs_room_to_reach_the_turn_lane(tmp_path):
    """Real towns split roads into pieces shorter than the lane-change cutoff just before a junction
    (CARLA Town10HD: 16 of 46 edges): a car on such a piece in a lane without a link onto the route's
    next edge can only leave the route."""
    net = _split_then_turn_net(tmp_path)
    assert net.edge_length["short"] < LANE_CHANGE_CUTOFF_M < net.edge_length["long"] - 20.0
    route = ("long", "short", "left")
    goal = net.edge_lanes["left"][0]
    right, left = net.edge_lanes["long"]
    assert net.route_drivable(route, right, 5.0, goal, 50.0)  # changes lanes on the long piece
    assert net.route_drivable(route, left, 95.0, goal, 50.0)  # already in the turn's lane
    assert not net.route_drivable(route, right, net.edge_length["long"] - 5.0, goal, 50.0)  # too late to change
    assert not net.route_drivable(route[1:], net.edge_lanes["short"][0], 1.0, goal, 50.0)
    assert net.route_drivable(route[1:], net.edge_lanes["short"][1], 1.0, goal, 50.0)
    # a goal on the short piece lies in the lane the car enters it by: no room to change there
    short_right, short_left = net.edge_lanes["short"]
    late = net.edge_length["long"] - 5.0
    assert net.route_drivable(route[:2], right, 5.0, short_left, 4.0)
    assert not net.route_drivable(route[:2], right, late, short_left, 4.0)
    assert net.route_drivable(route[:2], right, late, short_right, 4.0)
    # the goal lane: reached by a change on the goal edge before the goal, not after it
    assert net.route_drivable(("long",), right, 5.0, left, 60.0)
    assert not net.route_drivable(("long",), right, 5.0, left, 4.0)


def test_a_lane_change_needs_room_to_begin_before_the_cutoff():
    """Town03: ``Pl130_I90_130`` (one lane) lands on the right lane of ``-X90_95_I90_130``, a 12.5 m edge whose
    left lane alone turns onto ``X90_95_I125_95``: 2.5 m before the lane-change cutoff is no room to begin a
    change (the expert looped the block there until it timed out), so the route is not drivable; joining the
    12.5 m edge in its left lane it is."""
    net = road_network("Town03")
    route = ("Pl130_I90_130", "-X90_95_I90_130", "X90_95_I125_95")
    goal = "X90_95_I125_95_3"  # where the turn lands: no room for a change before a goal 8 m in
    assert not net.route_drivable(route, "Pl130_I90_130_1", 5.0, goal, 8.0)
    assert net.route_drivable(route[1:], "-X90_95_I90_130_2", 0.5, goal, 8.0)
    assert net.route_drivable(route, "Pl130_I90_130_1", 5.0, goal, 8.0, begin_m=0.0)  # the old rule's answer


def test_two_lane_changes_need_room_for_two():
    """Town03: leaving the roundabout by ``-AS_RS`` lands on the right lane of ``-I125_95_AS`` (16 m, three
    lanes), whose left lane alone turns onto ``-Pb125_I125_95``: 6 m before the cutoff is room for one change,
    not the two needed (the expert changed once and went straight on, then looped until it timed out)."""
    net = road_network("Town03")
    route = ("-AS_RS", "-I125_95_AS", "-Pb125_I125_95")
    goal = net.edge_lanes["-Pb125_I125_95"][0]
    assert not net.route_drivable(route, "-AS_RS_1", 5.0, goal, 30.0)
    assert net.route_drivable(route[1:], "-I125_95_AS_2", 0.0, goal, 30.0)   # one change: room for it
    assert not net.route_drivable(route[1:], "-I125_95_AS_1", 0.0, goal, 30.0)


@pytest.mark.parametrize("town", ["Town01", "Town02", "Town03", "Town04", "Town05"])
def test_a_car_turning_past_pedestrians_waiting_to_cross_clears_them(town):
    """Pedestrians wait on the kerb line across a crossing's width. With netconvert's 4 m crossings and
    5-point junction lanes the towns' right turns passed 0.35-1.25 m into them, and the lawful expert
    stood behind them through whole cycles (Town02 Nav. dynamic: 12 of 25 CoRL2017 episodes timed out)."""
    gap, lane, crossing = road_network(town).crossing_clearance()
    assert gap >= 0.0, (lane, crossing, gap)


def test_a_pose_on_another_level_is_not_within_reach():
    """Town04: the route of hbmp Navigation 18 drives Min_E_Kin_E, which passes over Dout_E_R_E; SUMO mapped the
    pushed pose onto the road below, the ego followed that lane and left its own road. Navigation 8 drives the
    ramp R_E_Mout_E over Kin_N_Din_E, which its route took earlier."""
    net = road_network("Town04")
    assert not net.within_reach("Min_E_Kin_E_0", "Dout_E_R_E_0")
    assert not net.within_reach("R_E_Mout_E_0", "Kin_N_Din_E_0")
    assert net.within_reach("Min_E_Kin_E_0", net.edge_lanes[net.successors("Min_E_Kin_E")[0]][0])
    assert net.within_reach("Kin_N_Din_E_0", "Kin_N_Din_E_1")  # a lane change
