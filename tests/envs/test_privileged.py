"""Privileged ``info["scene"]`` fields: the geometry of actors near the followed path, a light's
schedule read off its program, and the fields in a real episode."""

import math

import numpy as np
import pytest

from hbmp_bench.envs.privileged import LEADER_RANGE_M, path_actors
from hbmp_bench.planning.frame import Path

EGO_L, EGO_W = 4.5, 1.8


def _actors(*rows):
    """(xy, yaw, speed, length, width, is_pedestrian) arrays from (x, y, yaw, speed, is_pedestrian) rows."""
    a = np.array([r[:4] for r in rows], dtype=float).reshape(-1, 4)
    ped = np.array([r[4] for r in rows], dtype=bool)
    length = np.where(ped, 0.6, 4.5)
    width = np.where(ped, 0.6, 1.8)
    return a[:, :2], a[:, 2], a[:, 3], length, width, ped


def _straight():
    return Path(np.array([[-20.0, 0.0], [200.0, 0.0]]), max_spacing=1.0)


def test_path_actors_leader_is_the_nearest_actor_ahead_in_the_corridor():
    xy, yaw, speed, length, width, ped = _actors(
        (30.0, 0.0, 0.0, 5.0, False),           # ahead in the lane, driving away at 5 m/s
        (10.0, 3.5, 0.0, 9.0, False),           # in the next lane: not a leader
        (-10.0, 0.0, 0.0, 9.0, False),          # behind
    )
    out = path_actors(_straight(), np.zeros(2), EGO_L, EGO_W, xy, yaw, speed, length, width, ped)
    assert out["leader_gap_m"] == pytest.approx(30.0 - 2.25 - 2.25)
    assert out["leader_speed_mps"] == pytest.approx(5.0)
    assert out["pedestrians"] == ()


def test_path_actors_a_crossing_vehicle_leads_with_its_width_and_no_speed_along_the_path():
    xy, yaw, speed, length, width, ped = _actors((12.0, 0.0, math.pi / 2, 8.0, False), (30.0, 0.0, 0.0, 5.0, False))
    out = path_actors(_straight(), np.zeros(2), EGO_L, EGO_W, xy, yaw, speed, length, width, ped)
    assert out["leader_gap_m"] == pytest.approx(12.0 - 0.9 - 2.25, abs=1e-6)
    assert out["leader_speed_mps"] == pytest.approx(0.0, abs=1e-6)


def test_path_actors_reports_pedestrians_near_the_path_with_their_velocity():
    xy, yaw, speed, length, width, ped = _actors(
        (15.0, -4.0, math.pi / 2, 1.3, True),    # walking across from the right
        (25.0, 5.0, 0.0, 1.2, True),            # walking along on the left
        (25.0, 30.0, 0.0, 1.2, True),           # far to the side: not reported
    )
    out = path_actors(_straight(), np.zeros(2), EGO_L, EGO_W, xy, yaw, speed, length, width, ped)
    assert math.isinf(out["leader_gap_m"])
    (s0, d0, vs0, vd0, held0), (s1, d1, vs1, vd1, held1) = out["pedestrians"]
    assert (s0, d0) == pytest.approx((15.0 - 2.25, -4.0)) and (vs0, vd0) == pytest.approx((0.0, 1.3), abs=1e-6)
    assert (s1, d1) == pytest.approx((25.0 - 2.25, 5.0)) and (vs1, vd1) == pytest.approx((1.2, 0.0), abs=1e-6)
    assert not held0 and not held1
    held = path_actors(_straight(), np.zeros(2), EGO_L, EGO_W, xy, yaw, speed, length, width, ped,
                       np.array([True, False, True]))
    assert [p[4] for p in held["pedestrians"]] == [True, False]


def test_path_actors_follows_the_path_around_a_corner():
    corner = Path(np.array([[-20.0, 0.0], [0.0, 0.0], [0.0, 100.0]]), max_spacing=0.5)
    # 10 m before the corner; a car standing 20 m after it, in the lane after the turn
    xy, yaw, speed, length, width, ped = _actors((0.0, 20.0, math.pi / 2, 0.0, False))
    out = path_actors(corner, np.array([-10.0, 0.0]), EGO_L, EGO_W, xy, yaw, speed, length, width, ped)
    assert out["leader_gap_m"] == pytest.approx(10.0 + 20.0 - 2.25 - 2.25, abs=0.5)
    far = _actors((0.0, LEADER_RANGE_M + 20.0, math.pi / 2, 0.0, False))
    assert math.isinf(path_actors(corner, np.array([-10.0, 0.0]), EGO_L, EGO_W, *far)["leader_gap_m"])


@pytest.mark.slow
def test_signal_schedule_predicts_the_link_signal_seen_in_sumo():
    from hbmp_bench.maps import net_path
    from hbmp_bench.maps.roadnet import load_road_network
    from hbmp_bench.sim.sumo import SumoSim

    net = load_road_network(str(net_path("Town01")))
    link = next(c for conns in net.connections.values() for c in conns if c.tls)
    sim = SumoSim(net_path("Town01"), step_length=0.1)
    sim.start(seed=0)
    try:
        for _ in range(37):
            sim.step()
        schedule = sim.signal_schedule(link.tls, link.link_index, horizon_s=60.0)
        start = sim.time
        seen = []
        while sim.time - start < 60.0:
            seen.append((sim.time - start, sim.light_state(link.tls, link.link_index)))
            sim.step()
    finally:
        sim.close()
    assert schedule[0] == (0.0, seen[0][1])
    changes = [(t, c) for (t, c), (_, before) in zip(seen[1:], seen[:-1]) if c != before]
    assert len(changes) >= 2  # a fixed-time program changes within a minute
    assert [c for _, c in schedule[1:len(changes) + 1]] == [c for _, c in changes]
    assert [t for t, _ in schedule[1:len(changes) + 1]] == pytest.approx([t for t, _ in changes], abs=0.11)


def test_lights_ahead_off_the_route_are_the_ones_the_detectors_judge():
    """Past a goal it missed, on the route's continuation (no edge of the route), the ego still sees
    the light ending its lane: the one the red-light detector judges. Town03 NavigationDynamic 4 and
    39 (continuous) entered a short goal edge one lane off, drove on and ran the next red blind."""
    from types import SimpleNamespace

    from hbmp_bench.envs.vehicle import GoalRoute, followed_stop_line
    from hbmp_bench.metrics import LaneLocator
    from hbmp_bench.scenarios import road_network, suite_episodes
    from hbmp_bench.sim.sumo import LightAhead

    net = road_network("Town01")
    locator = LaneLocator(net)
    episode = suite_episodes("hbmp", "Town01", "NavigationDynamic")[0]
    lane = next(lane for lane in net.lanes  # a signalised lane off the route
                if net.lanes[lane].edge not in episode.route and locator.stop_line(lane, None) is not None)
    sim = SimpleNamespace(light_state=lambda tls, index: "r", light_ahead=lambda vehicle_id: None)
    route = GoalRoute(episode, "continuous")
    pos = net.lane(lane).length - 20.0  # 20 m before the stop line
    xy, ahead = net.position(lane, pos), net.position(lane, pos + 1.0)
    yaw = float(np.arctan2(*(ahead - xy)[::-1]))
    vehicle = SimpleNamespace(id="ego", shared=SimpleNamespace(net=net, sim=sim, locator=locator), followed_lane=lane,
                              state=SimpleNamespace(lane=lane, lane_pos=pos, xy=xy, yaw=yaw),
                              front=xy + 2.25 * np.array([np.cos(yaw), np.sin(yaw)]))
    vehicle.next_edges = lambda count=3: route.edges[route.index() + 1: route.index() + 1 + count]
    route.v = vehicle
    route._set(episode.route)

    judged = followed_stop_line(sim, locator, lane, next(iter(vehicle.next_edges(1)), None))
    lights = route._route_lights()
    assert judged is not None and len(lights) == 1
    assert (lights[0].state, lights[0].distance) == ("r", pytest.approx(20.0 - 2.25, abs=0.3))
    assert (lights[0].tls, lights[0].link_index) == locator.stop_line(lane, next(iter(vehicle.next_edges(1)), None))[2:]

    # on the route's last edge, past its end (in the junction after a goal it missed): SUMO's next
    # light on the route's continuation, for the expert (R_t keeps the route's lights only)
    goal = episode.goal_lane
    pos = net.lane(goal).length
    xy = net.position(goal, pos)
    vehicle.followed_lane, vehicle.state = goal, SimpleNamespace(lane=":junction", lane_pos=0.0, xy=xy, yaw=0.0)
    vehicle.front = xy
    sumo_next = LightAhead("tls", 3, 25.0, "r")
    sim.light_ahead = lambda vehicle_id: sumo_next
    assert sumo_next in route._route_lights() and sumo_next not in route._route_lights(first_only=True)


@pytest.mark.slow
@pytest.mark.parametrize("fidelity", ["continuous", "event"])
def test_privileged_fields_in_a_real_episode(fidelity):
    from hbmp_bench.agents import load_agent
    from hbmp_bench.envs import BehaviorEnv
    from hbmp_bench.envs.world import EGO_ID

    env = BehaviorEnv(town="Town01", task="NavigationDynamic", suite="hbmp", fidelity=fidelity, privileged=True)
    agent = load_agent("expert")
    obs, info = env.reset(seed=0, options={"episode_index": 0})
    agent.reset(info)
    seen = {"light": 0, "leader": 0, "pedestrian": 0, "foe": 0}
    try:
        for _ in range(400 if fidelity == "continuous" else 1500):
            scene = info["scene"]
            assert scene["fidelity"] == fidelity
            lights = scene["lights_ahead"]
            if lights:
                seen["light"] += 1
                assert [d for d, _, _ in lights] == sorted(d for d, _, _ in lights)
                for d, state, schedule in lights:
                    assert 0.0 <= d <= 150.0 and schedule[0] == (0.0, state)
                    assert all(a < b for (a, _), (b, _) in zip(schedule, schedule[1:]))
                if scene["light"]:  # the light ending the ego's lane is the first light on the route
                    assert lights[0][:2] == (pytest.approx(scene["stop_distance_m"]), scene["light"])
            if not scene["in_junction"] and math.isfinite(scene["junction_exit_m"]):
                assert scene["junction_exit_m"] >= scene["stop_distance_m"] - 0.5
            if math.isfinite(scene["leader_gap_m"]):
                seen["leader"] += 1
                assert scene["leader_gap_m"] >= 0.0
            seen["pedestrian"] += bool(scene["pedestrians"])
            for f in scene["junction_foes"]:
                seen["foe"] += 1
                assert f["ego_exit_m"] >= f["ego_dist_m"] and f["foe_exit_m"] >= f["foe_dist_m"]
                assert f["foe_speed_mps"] >= 0.0
            if fidelity == "continuous":  # SUMO's drivers see the ego's own speed, not a standing car
                assert env.world.sim.vehicle_state(EGO_ID).speed == pytest.approx(scene["speed_mps"], abs=1e-6)
            obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
            if terminated or truncated:
                break
    finally:
        env.close()
    assert all(n > 0 for n in seen.values()), seen


def test_gives_way_by_signal_or_link_state():
    from hbmp_bench.envs.privileged import gives_way

    assert gives_way("g", "o", "G", "o") and not gives_way("G", "o", "g", "o")
    assert not gives_way("g", "o", "g", "o")  # two permissive greens: neither has the right of way
    assert gives_way("", "m", "", "M") and gives_way("", "s", "", "M")
    assert not gives_way("", "M", "", "m") and not gives_way("", "=", "", "=")


def test_junction_foes_measures_both_cars_to_the_conflict_area():
    from hbmp_bench.envs.privileged import junction_foes
    from hbmp_bench.maps.roadnet import Connection, LinkConflict

    foe_link = Connection("a", "a_0", "b", "b_0", ":j_0_0", "s", "j", 3, "o")
    conflict = LinkConflict(foe_link, at_m=6.0, clear_m=9.0, foe_at_m=4.0, foe_clear_m=7.5)
    (approaching, inside), = [junction_foes(10.0, "g", "o", [conflict], [(("v1", 20.0, 8.0), ("v2", -2.0, 5.0))],
                                            ["G"])]
    assert approaching == {"ego_dist_m": 16.0, "ego_exit_m": 19.0, "foe_dist_m": 24.0, "foe_exit_m": 27.5,
                           "foe_speed_mps": 8.0, "ego_yields": True, "foe_yields": False, "foe_signal": "G",
                           "foe_speeding": False}
    assert inside["foe_dist_m"] == 2.0 and inside["foe_signal"] == ""  # inside the junction: its light is behind it
    # a foe well over its lane's limit (1.2 x) is speeding: a red will not hold it (scenario RedLightRunner)
    (fast, slow), = [junction_foes(10.0, "g", "o", [conflict], [(("v1", 20.0, 16.0), ("v2", 20.0, 13.0))], ["r"],
                                   [12.5])]
    assert fast["foe_speeding"] and not slow["foe_speeding"]


def _drive(privileged: bool, actions: list[int] | None = None, decisions: int = 300) -> tuple[list, list, list]:
    """(actions, observations, scenes) of the expert (or of the replayed ``actions``) on one
    event-fidelity episode with traffic lights, background vehicles and pedestrians."""
    from hbmp_bench.agents import load_agent
    from hbmp_bench.envs import BehaviorEnv

    env = BehaviorEnv(town="Town01", task="NavigationDynamic", suite="hbmp", fidelity="event", privileged=privileged)
    agent = load_agent("expert")
    taken, seen, scenes = [], [], []
    try:
        obs, info = env.reset(seed=0, options={"episode_index": 0})
        agent.reset(info)
        for k in range(decisions if actions is None else len(actions)):
            seen.append(obs)
            scenes.append(info["scene"])
            action = int(agent.act(obs, info)) if actions is None else actions[k]
            taken.append(action)
            obs, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
    finally:
        env.close()
    return taken, seen, scenes


@pytest.mark.slow
def test_a_default_env_builds_no_privileged_scene(monkeypatch):
    """Without ``privileged=True`` the scene holds R_t's quantities and the goal distance only,
    ``PrivilegedScene.fields`` is never called, and M_t and R_t are those of a privileged env."""
    from hbmp_bench.envs.privileged import PrivilegedScene
    from hbmp_bench.envs.scene import NON_PRIVILEGED_FIELDS

    actions, privileged_obs, privileged_scenes = _drive(privileged=True)
    assert any("lights_ahead" in s for s in privileged_scenes)

    def refuse(*args, **kwargs):
        raise AssertionError("PrivilegedScene.fields called in an env without privileged=True")

    monkeypatch.setattr(PrivilegedScene, "fields", refuse)
    _, default_obs, default_scenes = _drive(privileged=False, actions=actions)
    assert len(default_obs) == len(privileged_obs) > 50
    for plain, full in zip(default_scenes, privileged_scenes):
        assert set(plain) == set(NON_PRIVILEGED_FIELDS)
        assert plain == {k: full[k] for k in NON_PRIVILEGED_FIELDS}
    for plain, full in zip(default_obs, privileged_obs):
        assert np.array_equal(plain["road"], full["road"]) and np.array_equal(plain["occupancy"], full["occupancy"])
