"""Continuous fidelity: the motion planner drives the ego in SUMO (real libsumo, shipped nets)."""

import numpy as np
import pytest

from hbmp_bench.agents import load_agent
from hbmp_bench.envs.behavior_env import BehaviorEnv
from hbmp_bench.envs.config import WorldConfig
from hbmp_bench.envs.world import EGO_ID


def _run(env, agent_name="expert", max_steps=400):
    agent = load_agent(agent_name)
    obs, info = env.reset(seed=0)
    agent.reset(info)
    infos = []
    for _ in range(max_steps):
        obs, reward, terminated, truncated, info = env.step(agent.act(obs, info))
        infos.append((reward, info))
        if terminated or truncated:
            break
    return infos


def test_continuous_is_the_default_fidelity():
    assert WorldConfig().fidelity == "continuous"
    assert BehaviorEnv(town="Town01", task="Straight").config.fidelity == "continuous"
    with pytest.raises(ValueError, match="fidelity"):
        WorldConfig(fidelity="teleport")
    with pytest.raises(ValueError, match="reward"):
        WorldConfig(reward="shaped")


@pytest.mark.slow
def test_expert_reaches_the_goal_with_planner_rewards():
    env = BehaviorEnv(town="Town01", task="Straight", episode_index=0)
    steps = _run(env)
    reward, info = steps[-1]
    record = info["hbmp_record"]
    env.close()
    assert record["success"] and record["fidelity"] == "continuous"
    assert record["collision_vehicle"] + record["wrong_lane"] + record["off_road"] + record["red_light"] == 0
    durations = [i["duration_s"] for _, i in steps[:-1]]  # the goal cuts the last behavior short
    assert min(durations) > 0.1 and max(durations) <= 8.0 + 1e-6  # a behavior spans several 0.1 s steps
    r_k = [i["reward_components"]["r_k"] for _, i in steps]
    assert all(r <= 0.0 for r in r_k) and any(r < 0.0 for r in r_k)  # r_k = -c~_total
    for r, i in steps:
        assert r == pytest.approx(i["reward_components"]["r_k"] + i["reward_components"]["r_T"])
    assert set(info["planner_costs"]) >= {"c_total", "c_velocity", "c_dist", "c_obs"}


@pytest.mark.slow
def test_sparse_reward_pays_r_T_only():
    env = BehaviorEnv(town="Town01", task="Straight", episode_index=0, reward="sparse")
    steps = _run(env, max_steps=5)
    env.close()
    for r, i in steps:
        assert r == i["reward_components"]["r_T"]
        assert i["reward_components"]["r_k"] <= 0.0


@pytest.mark.slow
def test_ego_pose_in_sumo_follows_the_vehicle_model():
    """The model's pose is pushed into SUMO every step, so SUMO (and its traffic) see the ego there."""
    import libsumo

    env = BehaviorEnv(town="Town01", task="Straight", episode_index=0)
    env.reset(seed=0)
    for _ in range(3):
        env.step(0)  # speed_up
    world = env.world
    model = world.ego_driver.model
    front = np.array(libsumo.vehicle.getPosition(EGO_ID))
    centre = front - world.sim._dims[EGO_ID][0] / 2 * np.array([np.cos(model.yaw), np.sin(model.yaw)])
    env.close()
    assert model.v > 3.0
    assert np.hypot(*(centre - model.xy)) < 0.5


@pytest.mark.slow
def test_render_list_returns_frames_between_decisions():
    env = BehaviorEnv(town="Town01", task="Straight", episode_index=0, render_mode="rgb_array_list")
    env.reset(seed=0)
    first = env.render()
    _, _, _, _, info = env.step(0)
    frames = env.drain_frames()
    _, _, _, _, info2 = env.step(0)
    again = env.render()
    env.close()
    assert len(first) == 1 and env.render() == []  # each call returns the frames since the last one
    assert len(frames) == round(info["duration_s"] / 0.1)  # one per 0.1 s simulation step
    assert len(again) == round(info2["duration_s"] / 0.1)
    assert all(f.shape == (400, 400, 3) and f.dtype == np.uint8 for f in frames)


@pytest.mark.slow
def test_rgb_array_draws_on_demand_and_keeps_nothing():
    env = BehaviorEnv(town="Town01", task="Straight", episode_index=0, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(0)
    env.step(0)
    assert env.parallel._frames == [] and env.drain_frames() == []  # nothing drawn between decisions
    image = env.render()
    env.close()
    assert image.shape == (400, 400, 3) and image.dtype == np.uint8
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 10


@pytest.mark.slow
def test_route_is_replanned_only_once_lane_changes_are_closed():
    """A Town05 One turn episode that starts in a lane that does not continue the route: the route
    stays (the agent can still change lanes) until the lane's last metres, where it is re-planned
    from where that lane leads."""
    from hbmp_bench.scenarios import road_network, suite_episodes

    net = road_network("Town05")
    index = next(ep.index for ep in suite_episodes("corl2017", "Town05", "OneTurn")
                 if ep.start_lane not in net.lanes_to(ep.route[0], ep.route[1]))
    env = BehaviorEnv(town="Town05", task="OneTurn", episode_index=index, fidelity="event")
    env.reset(seed=1)
    ego = env.world.ego
    route = ego.route
    original = route.edges
    assert ego.followed_lane not in env.world.net.lanes_to(original[0], original[1])
    for _ in range(20):
        env.step(0)  # speed up, staying in the lane
    assert route.edges == original and route.reroutes == 0
    for _ in range(600):  # drive on in the wrong lane to its end
        _, _, terminated, truncated, _ = env.step(4)
        if route.reroutes or terminated or truncated:
            break
    env.close()
    assert route.reroutes == 1 and route.edges[0] == original[0] and route.edges[1] != original[1]
    assert route.edges[-1] == original[-1]  # still to the same goal edge


def test_no_reroute_over_a_link_too_sharp_to_drive():
    """Town03's lane X230_235_NE_1 leads only onto -Pr235_NE, by a link sharper than routes take
    (``RoadNetwork.links``). A policy that stayed in it to its end got the route re-planned over that link, and
    building the new route's path raised ValueError inside env.step (a random-init PPO worker died of it): the
    route now stays, as where a lane leads nowhere."""
    from types import SimpleNamespace

    from hbmp_bench.envs.vehicle import GoalRoute
    from hbmp_bench.scenarios import road_network

    net = road_network("Town03")
    edge, lane = "X230_235_NE", "X230_235_NE_1"
    assert net.lane_next[lane] and not any(lane in net.lanes_to(edge, to) for _, to in net.lane_next[lane])
    route = net.shortest_route(edge, "NE_Pt230")
    goal_lane = net.edge_lanes[route[-1]][0]
    episode = SimpleNamespace(route=route, start_lane=net.edge_lanes[edge][-1], goal_lane=goal_lane,
                              goal_pos=net.lane(goal_lane).length / 2)
    sim = SimpleNamespace(set_route=lambda vehicle_id, edges: True)
    vehicle = SimpleNamespace(id="ego", followed_lane=lane, shared=SimpleNamespace(net=net, sim=sim),
                              state=SimpleNamespace(lane=lane, lane_pos=net.lane(lane).length - 1.0))
    goal = GoalRoute(episode, "continuous")
    goal.v = vehicle
    goal._set(route)
    goal.keep()
    assert goal.edges == route and goal.reroutes == 0
