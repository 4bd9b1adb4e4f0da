"""Town04's outer ramps bridge over the inner carriageway: actors on the two levels never meet."""

import numpy as np
import pytest

from hbmp_bench.maps import net_path
from hbmp_bench.maps.roadnet import load_road_network
from hbmp_bench.maps.towns.town04 import BRIDGE_Z
from hbmp_bench.sim.sumo import LEVEL_CLEARANCE_M, Actors, SumoSim

RAMP, BELOW = "Dout_N_R_N", "Min_N_Kin_N"
"""The northern exit ramp and the inner carriageway it crosses (at about x = 480, y = 656)."""


def _actors(z):
    k = len(z)
    return Actors(tuple(f"a{i}" for i in range(k)), np.zeros((k, 2)), np.zeros(k), np.zeros(k), np.full(k, 4.5),
                  np.full(k, 1.8), np.zeros(k, bool), np.asarray(z, float))


def _segments_cross(p1, p2, q1, q2) -> bool:
    def side(a, b, c):
        return np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))
    return side(p1, p2, q1) != side(p1, p2, q2) and side(q1, q2, p1) != side(q1, q2, p2)


def test_around_keeps_the_actors_on_the_same_level():
    actors = _actors([0.0, 0.5, 2.9, 6.0, -4.0])
    assert actors.around("a0").ids == ("a1", "a2")
    assert actors.around("a3").ids == ()  # a2, 3.1 m below a bridge deck at 6 m: another level
    assert actors.around("ghost").ids == actors.ids  # an actor not in the snapshot sees everyone
    assert LEVEL_CLEARANCE_M < BRIDGE_Z


def test_the_ramp_crosses_the_carriageway_on_a_bridge():
    net = load_road_network(str(net_path("Town04")))
    ramp, below = net.lanes[f"{RAMP}_0"].shape, net.lanes[f"{BELOW}_1"].shape
    # the two lanes cross in the plane, without a junction
    assert any(_segments_cross(ramp[i, :2], ramp[i + 1, :2], below[j, :2], below[j + 1, :2])
               for i in range(len(ramp) - 1) for j in range(len(below) - 1))
    assert RAMP not in {c.to_lane.rsplit("_", 1)[0] for c in net.connections.get(BELOW, ())}


@pytest.mark.slow
def test_a_car_on_the_bridge_is_not_around_a_car_below():
    sim = SumoSim(net_path("Town04"), step_length=0.1)
    sim.start(seed=0)
    try:
        net = load_road_network(str(net_path("Town04")))
        ramp_len = net.edge_length[RAMP]
        below_len = net.edge_length[BELOW]
        # both about at the crossing point: the ramp's middle, and where the carriageway passes under
        sim.add_vehicle("up", (RAMP,), pos=0.5 * ramp_len)
        sim.add_vehicle("down", (BELOW,), lane_index=1, pos=0.5 * below_len)
        sim.step()
        snap = sim.snapshot()
        z = dict(zip(snap.ids, snap.z))
        assert z["up"] == pytest.approx(BRIDGE_Z, abs=0.5) and z["down"] == pytest.approx(0.0, abs=0.1)
        assert "up" not in snap.around("down").ids and "down" not in snap.around("up").ids
    finally:
        sim.close()
