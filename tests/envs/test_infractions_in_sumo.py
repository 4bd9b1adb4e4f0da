"""Infractions forced in real SUMO runs: run a red light, drive into a standing car, and pose
sequences pushed into SUMO the way the continuous driver pushes its vehicle model (real libsumo,
shipped Town01 net): red lights at speed, circling off the road beside a light, the opposite lane
through three junctions, and a clean expert episode through lights."""

import libsumo
import numpy as np
import pytest

from hbmp_bench.agents import agent_env_kwargs, load_agent
from hbmp_bench.envs import BehaviorEnv
from hbmp_bench.envs.config import WorldConfig
from hbmp_bench.envs.world import EGO_ID, DrivingWorld
from hbmp_bench.maps.roadnet import point_along
from hbmp_bench.planning import VehicleState as ModelState
from hbmp_bench.scenarios import suite_episodes
from hbmp_bench.sim.sumo import EGO_TYPE

pytestmark = pytest.mark.slow

DT = 0.1


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
    assert info["hbmp_record"]["red_light"] == total


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


# ------------------------------------------------------------------ pushed pose sequences
def _set_all_lights(signal):
    for tls in libsumo.trafficlight.getIDList():
        n = len(libsumo.trafficlight.getRedYellowGreenState(tls))
        libsumo.trafficlight.setRedYellowGreenState(tls, signal * n)


def _three_light_episode(net):
    """A Town01 Straight episode through three signalised junctions (and no traffic)."""
    for ep in suite_episodes("corl2017", "Town01", "Straight"):
        if len(ep.route) == 4 and all(net.links(a, b)[0].tls for a, b in zip(ep.route[:-1], ep.route[1:])):
            return ep
    raise AssertionError("a Town01 Straight episode crosses three signalised junctions")


def _route_centreline(net, ep):
    """(polyline (N, 2) [m] of the route's lane centres, junction lanes included; arc length [m] of
    each signalised stop line on it, i.e. the end of each approach lane whose link is signalised)."""
    lanes, lane = [ep.start_lane], ep.start_lane
    for edge in ep.route[1:]:
        while True:
            lane = net.follow(lane, edge)
            lanes.append(lane)
            if lane in net.lanes:
                break
    shapes = [net.lane(ln).shape for ln in lanes]
    ends = np.cumsum([np.hypot(*np.diff(sh, axis=0).T).sum() for sh in shapes])
    lines = [float(ends[i]) for i, ln in enumerate(lanes[:-1])
             if ln in net.lanes and any(c.tls for c in net.links(net.lane(ln).edge, ep.route[ep.route.index(net.lane(ln).edge) + 1]))]
    line = np.concatenate(shapes)
    return line[np.concatenate([[True], np.hypot(*np.diff(line, axis=0).T) > 1e-6])], lines


def _push(world, xy, yaw, speed):
    """One control period as the continuous driver runs it: the model's pose into SUMO, one SUMO
    step, the world's detection."""
    world.ego_driver.model = ModelState(float(xy[0]), float(xy[1]), float(yaw), float(speed))
    world.ego_driver.off_map = not world.sim.move_to_xy(EGO_ID, xy, yaw)
    world.sim.step()
    return world.ego.after_sim_step(world.sim.snapshot())


def _drive_polyline(world, line, start_s, end_s, speed, left_offset=0.0):
    """Push poses along ``line`` from arc ``start_s`` to ``end_s`` [m] at ``speed`` [m/s]; returns
    SUMO's lane of the ego after every step."""
    lanes = []
    for s in np.arange(start_s + speed * DT, end_s, speed * DT):
        xy, ahead = point_along(line, s), point_along(line, s + 1.0)
        yaw = float(np.arctan2(*(ahead - xy)[::-1]))
        _push(world, xy + left_offset * np.array([-np.sin(yaw), np.cos(yaw)]), yaw, speed)
        lanes.append(world.sim.vehicle_state(EGO_ID).lane)
    return lanes


@pytest.fixture
def world():
    w = DrivingWorld("Town01", WorldConfig(fidelity="continuous"))
    yield w
    w.close()


@pytest.mark.parametrize("speed", [10.0, 40.0])
@pytest.mark.parametrize("signal", ["r", "G"])
def test_red_lights_crossed_at_speed_are_one_event_each(world, speed, signal):
    """Along the route's lanes through three signalised junctions, all lights red (or green): the
    ground truth is the number of stop lines the front bumper passes, from the route's geometry."""
    ep = _three_light_episode(world.net)
    line, stop_lines = _route_centreline(world.net, ep)
    world.start(ep, seed=0)
    _set_all_lights(signal)
    start, end = ep.start_pos - EGO_TYPE.length / 2, stop_lines[-1] + 20.0
    _drive_polyline(world, line, start, end, speed)
    front_start, front_end = start + EGO_TYPE.length / 2, end + EGO_TYPE.length / 2
    truth = sum(front_start < x <= front_end for x in stop_lines) if signal == "r" else 0
    assert len(stop_lines) == 3
    assert world.ego.detector.totals["red_light"] == truth
    assert world.ego.detector.totals["wrong_lane"] + world.ego.detector.totals["off_road"] == 0


def test_circling_off_the_road_beside_a_red_light_is_no_red_light_and_one_off_road(world):
    """Circling at 10 m/s 8 m beside the first stop line (never on a lane): SUMO's map matching of the
    pushed pose flips between the approach lane and the junction lane (and its light ahead with it),
    which must not produce red lights; the excursion is one off-road event."""
    ep = _three_light_episode(world.net)
    net = world.net
    lane = net.lane(ep.start_lane)
    world.start(ep, seed=0)
    _set_all_lights("r")
    end = lane.shape[-1]
    direction = (lane.shape[-1] - lane.shape[-2]) / np.hypot(*(lane.shape[-1] - lane.shape[-2]))
    right = np.array([direction[1], -direction[0]])
    centre, radius, speed = end - 8.0 * right, 5.0, 10.0
    sumo_lanes = []
    for k in range(150):  # 15 s, about 5 laps
        angle = np.pi / 2 - speed / radius * DT * k
        xy = centre + radius * (np.cos(angle) * right + np.sin(angle) * direction)
        tangent = np.sin(angle) * right - np.cos(angle) * direction  # clockwise in the plane
        yaw = float(np.arctan2(tangent[1], tangent[0]))
        _push(world, xy, yaw, speed)
        sumo_lanes.append(world.sim.vehicle_state(EGO_ID).lane)
    flips = sum(a != b for a, b in zip(sumo_lanes[:-1], sumo_lanes[1:]))
    assert flips >= 6 and lane.id in sumo_lanes and any(ln.startswith(":") for ln in sumo_lanes)
    assert world.ego.detector.totals["red_light"] == 0
    assert world.ego.detector.totals["off_road"] == 1 and world.ego.detector.totals["wrong_lane"] == 0


def test_opposite_lane_across_three_junctions_is_one_wrong_lane_event(world):
    ep = _three_light_episode(world.net)
    line, stop_lines = _route_centreline(world.net, ep)
    world.start(ep, seed=0)
    width = world.net.lane(ep.start_lane).width
    _drive_polyline(world, line, ep.start_pos + 5.0, stop_lines[-1] + 20.0, 10.0, left_offset=width)
    assert world.ego.detector.totals["wrong_lane"] == 1
    assert world.ego.detector.totals["off_road"] == 0


def test_expert_stops_at_red_lights_and_drives_a_clean_episode():
    """The expert through three signalised junctions on SUMO's own light programs: it waits at a red
    light at least once, reaches the goal and no detector fires. The first light starts in the phase
    that serves the cross street (its program runs on from there), so the ego meets a red whatever
    the towns' green times."""
    agent = load_agent("expert")
    env = BehaviorEnv(town="Town01", task="Straight", episode_index=0, **agent_env_kwargs(agent))
    obs, info = env.reset(seed=0)
    ep = env.world.episode
    assert ep == _three_light_episode(env.world.net)
    first = env.world.net.links(ep.route[0], ep.route[1])[0]
    (logic,) = libsumo.trafficlight.getAllProgramLogics(first.tls)
    cross = next(k for k, ph in enumerate(logic.phases) if ph.state[first.link_index] == "r" and "G" in ph.state)
    libsumo.trafficlight.setPhase(first.tls, cross)
    agent.reset(info)
    waited_at_red = 0
    for _ in range(400):
        obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
        waited_at_red += info["scene"]["speed_mps"] < 0.1 and env.world.sim.light_ahead(EGO_ID) is not None \
            and env.world.sim.light_ahead(EGO_ID).state in "rR"
        if terminated or truncated:
            break
    record = info["hbmp_record"]
    env.close()
    assert record["success"]
    assert waited_at_red > 0
    assert {k: record[k] for k in ("collision_vehicle", "collision_pedestrian", "wrong_lane", "off_road", "red_light")} \
        == dict.fromkeys(("collision_vehicle", "collision_pedestrian", "wrong_lane", "off_road", "red_light"), 0)
