"""Infractions forced in real SUMO runs: run a red light, drive into a standing car."""

import libsumo
import numpy as np
import pytest

from hbmp_bench.envs import BehaviorEnv
from hbmp_bench.envs.world import EGO_ID

pytestmark = pytest.mark.slow


def _episode_through_a_light(env):
    net = env.world.net
    for i, ep in enumerate(env.episodes):
        links = [c for a, b in zip(ep.route[:-1], ep.route[1:]) for c in net.links(a, b)]
        if any(c.tls for c in links):
            return i
    raise AssertionError("no Straight episode crosses a signalised junction")


def test_driving_through_red_is_detected():
    env = BehaviorEnv(town="Town01", task="Straight")
    index = _episode_through_a_light(env)
    env.reset(seed=0, options={"episode_index": index})
    for tls in libsumo.trafficlight.getIDList():
        n = len(libsumo.trafficlight.getRedYellowGreenState(tls))
        libsumo.trafficlight.setRedYellowGreenState(tls, "r" * n)
    total = 0
    for _ in range(2000):
        _, reward, terminated, truncated, info = env.step(0)  # speed_up, never stop
        total += info["events"]["red_light"]
        if info["events"]["red_light"]:
            assert reward <= -10.0
        if terminated or truncated:
            break
    env.close()
    assert total >= 1
    assert info["episode"]["red_light"] == total


def _speed_up_towards_a_standing_car(fidelity: str) -> tuple[int, dict]:
    env = BehaviorEnv(town="Town02", task="Straight", episode_index=0, fidelity=fidelity)
    env.reset(seed=0)
    world = env.world
    ego = world.sim.vehicle_state(EGO_ID)
    lane = world.net.lane(ego.lane)
    world.sim.add_vehicle("blocker", (lane.edge,), lane_index=lane.index, pos=min(ego.lane_pos + 25.0, lane.length - 1.0), speed=0.0)
    libsumo.vehicle.setSpeed("blocker", 0.0)
    collisions, info = 0, {}
    for _ in range(150):
        _, reward, terminated, truncated, info = env.step(0)
        collisions += info["events"]["collision_vehicle"]
        if terminated or truncated or info["time_s"] > 40.0:
            break
    env.close()
    return collisions, info


def test_driving_into_a_standing_car_is_one_collision():
    """Event fidelity: SUMO follows speed_up into the car; the contact is counted once."""
    collisions, _ = _speed_up_towards_a_standing_car("event")
    assert collisions == 1


def test_the_motion_planner_does_not_drive_into_a_standing_car():
    """Continuous fidelity: speed_up only raises v_ref; the planner's collision check brakes."""
    collisions, info = _speed_up_towards_a_standing_car("continuous")
    assert collisions == 0
    assert info["scene"]["speed_mps"] < 0.5  # stopped behind it
