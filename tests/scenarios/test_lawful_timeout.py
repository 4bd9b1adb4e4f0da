"""A lawful driver meets every episode's timeout through the towns' real signal programs, and the
towns' greens clear the queues of the suites' traffic."""

from __future__ import annotations

import math

import libsumo
import numpy as np
import pytest
import sumo

from hbmp_bench.maps import TOWNS, net_path
from hbmp_bench.maps.signals import queue_cleared, read_programs
from hbmp_bench.maps.towns import town_spec
from hbmp_bench.scenarios import SUITES, get_suite, road_network, suite_episodes, traffic_for
from hbmp_bench.scenarios.lawful import LAWFUL_ACCEL, lawful_travel_time, route_signals
from hbmp_bench.sim.sumo import EGO_TYPE

FRACTIONS = np.round(np.arange(0.6, 1.0 + 1e-9, 0.02), 2)
"""Cruise speeds of the lawful drivers, as fractions of each lane's limit."""
DEPARTURES_S = (0.0, 1.0, 2.0)
"""When the lawful drivers set off after the episode start [s] (a slow start)."""
POSE_TASKS = ("Straight", "OneTurn", "Navigation")
"""Navigation dynamic drives Navigation's routes with Navigation's timeouts."""


def test_model_driver_accelerates_like_the_ego():
    assert LAWFUL_ACCEL == EGO_TYPE.accel


@pytest.mark.parametrize("suite", ["corl2017", "hbmp", "nocrash-regular"])  # the NoCrash densities share poses
@pytest.mark.parametrize("town", TOWNS)
def test_lawful_driver_meets_every_timeout(suite, town):
    late = []
    for task in (t for t in POSE_TASKS if t in get_suite(suite).tasks):
        for ep in suite_episodes(suite, town, task):
            worst = max(lawful_travel_time(ep, f, depart_s=d) for f in FRACTIONS for d in DEPARTURES_S)
            if worst > ep.timeout_s:
                late.append((ep.key, round(worst, 1), ep.timeout_s))
    assert not late, late


def _sumo_arrival_s(ep, speed_factor: float) -> float:
    """Simulation time [s] at which SUMO's own driver (Krauss without dawdling, the ego's length and
    acceleration), sent along the episode's route from a standstill at its start, arrives at its goal
    through the town's lights (inf if not within the timeout + 60 s)."""
    libsumo.start([str(sumo.SUMO_HOME) + "/bin/sumo", "-n", str(net_path(ep.town)), "--step-length", "0.1",
                   "--no-step-log", "true", "--no-warnings", "true", "--default.speeddev", "0"])
    try:
        libsumo.vehicletype.copy("DEFAULT_VEHTYPE", "lawful")
        libsumo.vehicletype.setAccel("lawful", EGO_TYPE.accel)
        libsumo.vehicletype.setDecel("lawful", EGO_TYPE.decel)
        libsumo.vehicletype.setLength("lawful", EGO_TYPE.length)
        libsumo.vehicletype.setImperfection("lawful", 0.0)
        libsumo.vehicletype.setSpeedFactor("lawful", speed_factor)
        libsumo.route.add("route", list(ep.route))
        lane = road_network(ep.town).lane(ep.start_lane)
        libsumo.vehicle.add("lawful", "route", typeID="lawful", departLane=str(lane.index), departPos=str(ep.start_pos),
                            departSpeed="0", arrivalPos=str(ep.goal_pos))
        while libsumo.simulation.getTime() < ep.timeout_s + 60.0:
            libsumo.simulationStep()
            if "lawful" in libsumo.simulation.getArrivedIDList():
                return libsumo.simulation.getTime()
        return math.inf
    finally:
        libsumo.close()


@pytest.mark.slow
@pytest.mark.parametrize(("suite", "town"), [("corl2017", t) for t in TOWNS] + [("hbmp", "Town02"), ("hbmp", "Town03")])
def test_sumo_driver_meets_every_timeout(suite, town):
    """A second lawful driver with other dynamics: SUMO's own, which brakes for a yellow it can stop for,
    slows for turns and changes lanes itself, at 80 % and 100 % of the limits."""
    late = []
    for task in POSE_TASKS:
        for ep in suite_episodes(suite, town, task):
            for factor in (0.8, 1.0):
                arrival = _sumo_arrival_s(ep, factor)
                if arrival > ep.timeout_s:
                    late.append((ep.key, factor, arrival, ep.timeout_s))
    assert not late, late


def test_one_signal_costs_at_most_its_longest_red():
    """On a route with one signal, the departure that meets the start of its red loses the whole red
    and the re-acceleration; one that meets its green loses nothing."""
    ep = next(e for e in suite_episodes("corl2017", "Town01", "Straight") if len(route_signals(e)) == 1)
    (signal,) = route_signals(ep)
    program = read_programs(net_path("Town01"))[signal.link.tls]
    f = 0.8
    spent = [lawful_travel_time(ep, f, depart_s=d) - d for d in np.arange(0.0, program.cycle, 0.1)]
    lost = program.longest_red(signal.link.link_index) + f * signal.speed / (2 * LAWFUL_ACCEL)
    assert max(spent) - min(spent) == pytest.approx(lost, abs=0.11)


def test_travel_time_model():
    ep = suite_episodes("corl2017", "Town02", "Navigation")[0]
    signals = route_signals(ep)
    assert signals and all(s.link.tls for s in signals)
    assert [s.at_m for s in signals] == sorted(s.at_m for s in signals)
    net = road_network("Town02")
    free = ep.route_length_m / net.lane(ep.start_lane).speed
    for f in (0.6, 0.8, 1.0):
        assert lawful_travel_time(ep, f) >= free / f  # never faster than the limit allows
    with pytest.raises(ValueError):
        lawful_travel_time(ep, 0.0)
    with pytest.raises(ValueError):
        lawful_travel_time(ep, 0.8, accel=0.0)


def test_a_route_without_signals_is_driven_at_the_cruise_speed():
    for ep in suite_episodes("corl2017", "Town03", "Straight"):
        if not route_signals(ep):
            break
    else:
        pytest.skip("every route has a signal")
    net = road_network("Town03")
    t = lawful_travel_time(ep, 1.0)
    v = net.lane(ep.start_lane).speed
    assert ep.route_length_m / v < t <= ep.route_length_m / v * 1.5 + v / (2 * LAWFUL_ACCEL)


def _poisson_quantile(q: float, mean: float) -> int:
    k, p = 0, math.exp(-mean)
    total = p
    while total < q:
        k += 1
        p *= mean / k
        total += p
    return k


@pytest.mark.parametrize("town", TOWNS)
def test_greens_clear_the_densest_suites_queues(town):
    """A main phase's green clears, with 99 % probability, every vehicle a lane holds when the densest
    suite's traffic spreads over the town's lanes (Poisson counts per lane)."""
    net = road_network(town)
    vehicles = max(traffic_for(town, task, s.density).vehicles for s in SUITES.values() for task in s.tasks)
    queue = _poisson_quantile(0.99, vehicles / len(net.lanes))
    assert queue_cleared(town_spec(town).green_s) >= queue, (town, vehicles, queue)
    programs = read_programs(net_path(town))
    assert all(p.green(k) >= town_spec(town).green_s for p in programs.values() for k in p.vehicle_links)
