"""Scenario types: their episodes are a pure function of the suite, and each hazard is set up in SUMO as
specified, checked from what SUMO reports at every step (not from what the script says it did)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hbmp_bench.agents import load_agent
from hbmp_bench.envs.config import WorldConfig
from hbmp_bench.envs.world import EGO_ID, DrivingWorld
from hbmp_bench.scenarios import SCENARIO_TYPES, get_suite, road_network, suite_episodes
from hbmp_bench.scenarios.scenario_types import HardBrake, PedestrianStepsOut
from hbmp_bench.scenarios.suites import episode_list


def test_every_scenario_episode_fits_its_type_and_is_drawn_again_the_same():
    for name, kind in SCENARIO_TYPES.items():
        for town in ("Town02", "Town04"):
            episodes = episode_list("scenarios", town, name)
            assert episodes == episode_list("scenarios", town, name)
            assert all(ep.task == name and kind.fits(road_network(town), ep) for ep in episodes)


def test_a_town_that_cannot_host_a_type_has_no_episodes_of_it():
    assert suite_episodes("scenarios", "Town01", "CutIn") == ()  # one lane each way: nowhere to cut in from
    assert len(suite_episodes("scenarios", "Town04", "CutIn")) == get_suite("scenarios").episodes_per_task


def test_the_held_out_suite_draws_other_episodes_of_the_same_types():
    suite, held = get_suite("scenarios"), get_suite("scenarios-heldout")
    assert suite.tasks == held.tasks and suite.seed != held.seed
    a, b = suite_episodes("scenarios", "Town03", "HardBrake"), suite_episodes("scenarios-heldout", "Town03", "HardBrake")
    assert {(e.start_lane, e.start_pos) for e in a}.isdisjoint({(e.start_lane, e.start_pos) for e in b})


def drive(town: str, task: str, index: int, watch) -> tuple[dict, DrivingWorld]:
    """One event-fidelity episode with the expert; ``watch(world)`` after every SUMO step."""
    world = DrivingWorld(town, WorldConfig(fidelity="event", privileged=True))
    episode = suite_episodes("scenarios", town, task)[index]
    agent = load_agent("expert")
    obs, infos = world.start(episode, seed=0)
    agent.reset(infos[EGO_ID])
    try:
        for _ in range(20000):
            action = agent.act(obs[EGO_ID], infos[EGO_ID])
            o, _, terms, truncs, i = world.step({EGO_ID: action}, on_substep=lambda: watch(world))
            obs, infos = o, i
            if terms[EGO_ID] or truncs[EGO_ID]:
                return world.record().to_dict(), world
        raise AssertionError("the episode did not end")
    finally:
        world.close()


def _state(world, vid):
    return world.sim.vehicle_state(vid)


@pytest.mark.slow
def test_the_leader_brakes_hard_in_front_of_the_ego():
    seen = []

    def watch(world):
        leader, ego = _state(world, HardBrake.LEADER), _state(world, EGO_ID)
        if leader is not None and ego is not None:
            heading = np.array([math.cos(ego.yaw), math.sin(ego.yaw)])
            d = leader.xy - ego.xy
            ahead, across = float(d @ heading), float(heading[0] * d[1] - heading[1] * d[0])
            seen.append((world.sim.time, leader.speed, ahead, across, float(np.hypot(*(leader.xy - ego.xy)))))

    record, world = drive("Town01", "HardBrake", 0, watch)
    t, v = np.array([s[0] for s in seen]), np.array([s[1] for s in seen])
    decel = -np.diff(v) / np.diff(t)
    assert decel.max() > 6.0  # a hard brake, not SUMO's comfortable 4.5 m/s²
    k = int(np.argmax(decel))
    assert v[k] > 6.0 and 0.0 < seen[k][2] < 35.0  # from speed, close ahead of the ego
    assert abs(seen[k][3]) < 2.0  # in its lane (or the junction lane its route takes), not beside it
    assert record["success"] and record["collision_vehicle"] == 0


@pytest.mark.slow
def test_the_cut_in_car_changes_into_the_ego_lane_close_ahead():
    seen = []

    def watch(world):
        cutter, ego = _state(world, "sc_cutter"), _state(world, EGO_ID)
        if cutter is not None and ego is not None and not cutter.lane.startswith(":") and not ego.lane.startswith(":"):
            seen.append((cutter.lane, ego.lane, cutter.lane_pos - 4.5 - ego.lane_pos, cutter.speed - ego.speed))

    record, _ = drive("Town04", "CutIn", 0, watch)
    first_same = next(k for k, s in enumerate(seen) if s[0] == s[1])
    assert first_same > 0 and seen[first_same - 1][0] != seen[first_same - 1][1]  # came from the next lane
    assert 3.0 <= seen[first_same][2] <= 9.0  # its rear 4-8 m ahead of the ego's front (a step of motion)
    assert seen[first_same][3] > 1.0  # faster than the ego
    assert record["collision_vehicle"] == 0


@pytest.mark.slow
def test_the_pedestrian_walks_across_the_egos_lane_ahead_of_it():
    seen = []

    def watch(world):
        snap, ego = world.sim.snapshot(), _state(world, EGO_ID)
        if PedestrianStepsOut.PERSON in snap.ids and ego is not None:
            p = snap.xy[snap.ids.index(PedestrianStepsOut.PERSON)]
            seen.append((world.sim.time, p.copy(), ego.xy.copy(), ego.speed, ego.yaw))

    record, world = drive("Town01", "PedestrianStepsOut", 0, watch)
    seen = seen[1:]  # inserted on a sidewalk, they are put at their kerb in the first step
    xy = np.array([s[1] for s in seen])
    assert np.hypot(*(xy[0] - world.script.kerb)) < 0.1
    assert np.hypot(*(xy[-1] - xy[0])) > 5.0  # walked across the road
    step = np.hypot(*np.diff(xy, axis=0).T) / 0.1
    assert 1.0 < step[step > 0.01].mean() < 2.0  # at a walking pace
    # when they set off, the ego was behind them, within its stopping room and a margin, and could stop
    k = int(np.argmax(step > 0.01))
    _, p, e, v, yaw = seen[k]
    ahead = float(np.dot(p - e, [math.cos(yaw), math.sin(yaw)]))
    assert 0.0 < ahead < 60.0 and ahead > v * 1.0 + v * v / (2 * 4.5)
    assert record["success"] and record["collision_pedestrian"] == 0


@pytest.mark.slow
@pytest.mark.parametrize("town, task", [("Town03", "UnprotectedLeft"), ("Town05", "GiveWay")])
def test_a_stream_of_cars_crosses_the_egos_path_at_its_junction(town, task):
    seen = set()

    def watch(world):
        seen.update(v for v in world.sim.vehicle_ids() if v.startswith("sc_cross"))

    record, world = drive(town, task, 0, watch)
    hazard = world.script.hazard
    assert hazard is not None and hazard.foe.from_edge != hazard.link.from_edge
    assert len(seen) >= 4
    assert record["collision_vehicle"] == 0


@pytest.mark.slow
def test_the_red_light_runner_crosses_on_its_red_across_the_egos_green():
    seen = []

    def watch(world):
        runner = _state(world, "sc_runner")
        hazard = world.script.hazard
        if runner is not None:
            foe, link = hazard.foe, hazard.link
            seen.append((runner.lane, runner.speed, world.sim.light_state(foe.tls, foe.link_index),
                         world.sim.light_state(link.tls, link.link_index)))

    record, world = drive("Town03", "RedLightRunner", 0, watch)
    foe = world.script.hazard.foe
    limit = road_network("Town03").lane(foe.from_lane).speed
    entered = next(k for k, s in enumerate(seen) if s[0].startswith(":"))  # its first step in the junction
    lane, speed, its_signal, ego_signal = seen[entered - 1]  # the step before: at its stop line
    assert lane == foe.from_lane and its_signal in "rR" and ego_signal in "gG"
    assert speed > 1.2 * limit  # what a lawful driver can see coming
    assert record["success"] and record["collision_vehicle"] == 0


@pytest.mark.slow
def test_the_merge_stream_drives_onto_the_egos_next_edge():
    seen = set()

    def watch(world):
        for v in world.sim.vehicle_ids():
            if v.startswith("sc_cross"):
                seen.add(v)

    record, world = drive("Town04", "Merge", 0, watch)
    hazard = world.script.hazard
    assert hazard.foe.to_edge == hazard.link.to_edge and hazard.link.state == "m" and hazard.foe.state == "M"
    assert len(seen) >= 6
    assert record["collision_vehicle"] == 0


def test_long_routes_chain_several_shortest_routes_without_driving_an_edge_twice():
    from hbmp_bench.scenarios.suites import mean_route_lengths

    for town in ("Town01", "Town04"):
        for ep in suite_episodes("scenarios", town, "LongRoute"):
            assert ep.route_length_m >= 2.0 * mean_route_lengths(town)[2] and ep.turns >= 3
            assert len(set(ep.route)) == len(ep.route)
            assert road_network(town).route_drivable(ep.route, ep.start_lane, ep.start_pos, ep.goal_lane, ep.goal_pos)


def test_each_type_has_an_env_id_in_the_towns_that_host_it():
    from hbmp_bench.envs.registration import SCENARIO_SUITE, SCENARIO_TOWNS, env_ids
    from hbmp_bench.maps import TOWNS

    assert set(SCENARIO_TOWNS) == set(SCENARIO_TYPES)
    for name in SCENARIO_TYPES:
        hosts = tuple(t for t in TOWNS if suite_episodes(SCENARIO_SUITE, t, name))
        assert SCENARIO_TOWNS[name] == hosts, name
        assert {f"hbmp_bench/{t}-{name}-v0" for t in hosts} <= set(env_ids())
        assert not {f"hbmp_bench/{t}-{name}-v0" for t in TOWNS if t not in hosts} & set(env_ids())
