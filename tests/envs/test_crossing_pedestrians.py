"""SUMO's pedestrians and a car that stops on their crossing while they are on it (real libsumo, shipped
Town01 net, the package's SUMO options, the car driven as the continuous driver drives the ego: handed
over, its pose pushed each step): they wait beside the car however long it stands, and never walk
through it. SUMO's default lets a pedestrian held on a crossing for 10 s squeeze through whatever holds it
(``--pedestrian.striping.jamtime.crossing``), which the package's detectors would count as the car's
collision with a pedestrian."""

import math

import libsumo
import pytest

from hbmp_bench.maps.registry import net_path
from hbmp_bench.sim.sumo import EGO_TYPE, SumoSim

pytestmark = pytest.mark.slow

# Junction M1a of Town01: the car drives east on W1_M1a lane 1 (centre line y = 106.25 m) straight through
# the junction onto M1a_S1b; crossing :M1a_c1_0 spans x = 72.5..74.5 m over M1a_S1b and is green for
# pedestrians from t = 25.4 s to 40.4 s.
ROUTE = ("W1_M1a", "M1a_S1b")
LANE_Y = 106.25  # [m]
CROSSING = ":M1a_c1_0"
STOP_CENTRE_X = 75.0  # the car's rear 1.75 m over the crossing [m]
START_CENTRE_X, CRUISE, BRAKE = 30.0, 8.0, 3.0  # [m], [m/s], [m/s²]
GO_S = 21.5  # the car leaves then, and reaches the crossing after the pedestrians stepped onto it [s]
WALKS = (("M1a_S1b", 4.0, "-M1a_S1b", 12.0), ("-M1a_S1b", 42.0, "M1a_S1b", 12.0), ("M1a_S1b", 7.0, "-M1a_S1b", 25.0))
"""Pedestrians as (from edge, position [m], to edge, departure [s]): two wait at the kerbs for the green,
one arrives during it."""


def _distance_to_footprint(point, centre, yaw, length, width) -> float:
    """Distance [m] from ``point`` (x, y) to a length x width rectangle at ``centre`` heading ``yaw`` [rad]."""
    dx, dy = point[0] - centre[0], point[1] - centre[1]
    along = dx * math.cos(yaw) + dy * math.sin(yaw)
    across = -dx * math.sin(yaw) + dy * math.cos(yaw)
    return math.hypot(max(abs(along) - length / 2, 0.0), max(abs(across) - width / 2, 0.0))


def test_pedestrians_held_on_a_crossing_by_a_standing_car_never_walk_through_it():
    sim = SumoSim(net_path("Town01"))
    sim.start(seed=1)
    length, width = EGO_TYPE.length, EGO_TYPE.width
    try:
        sim.add_vehicle("car", ROUTE, lane_index=1, pos=START_CENTRE_X + length / 2 - 9.5, speed=0.0, vtype=EGO_TYPE)
        sim.hand_over("car")
        x = START_CENTRE_X
        added, held_on_crossing_s, inside_steps, stood_s = set(), {}, 0, 0.0
        while sim.time < 80.0:
            for i, (edge, pos, to_edge, depart) in enumerate(WALKS):
                if f"p{i}" not in added and sim.time >= depart:
                    sim.add_pedestrian(f"p{i}", edge, pos, [(edge, to_edge)])
                    added.add(f"p{i}")
            left = STOP_CENTRE_X - x
            speed = 0.0 if sim.time < GO_S or left < 0.02 else min(CRUISE, math.sqrt(2 * BRAKE * left), left / 0.1)
            x += speed * 0.1
            assert sim.move_to_xy("car", (x, LANE_Y), 0.0)
            sim.set_speed("car", speed)
            sim.step()
            front = libsumo.vehicle.getPosition("car")
            yaw = math.radians(90.0 - libsumo.vehicle.getAngle("car"))
            centre = (front[0] - length / 2 * math.cos(yaw), front[1] - length / 2 * math.sin(yaw))
            car_stands = libsumo.vehicle.getSpeed("car") < 0.01 and sim.time > GO_S + 1.0
            stood_s += 0.1 if car_stands else 0.0
            for pid in libsumo.person.getIDList():
                if car_stands and libsumo.person.getLaneID(pid) == CROSSING and libsumo.person.getSpeed(pid) < 0.1:
                    held_on_crossing_s[pid] = held_on_crossing_s.get(pid, 0.0) + 0.1
                if _distance_to_footprint(libsumo.person.getPosition(pid), centre, yaw, length, width) < 0.05:
                    inside_steps += 1
    finally:
        sim.close()
    assert abs(centre[0] - STOP_CENTRE_X) < 0.5 and stood_s > 40.0, "the car did not stop on the crossing"
    assert inside_steps == 0, "pedestrians walked through the standing car"
    # the case under test: held on the crossing by the car for longer than SUMO's default jam time (10 s)
    assert max(held_on_crossing_s.values(), default=0.0) > 20.0, held_on_crossing_s
