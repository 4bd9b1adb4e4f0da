"""The highway-env transfer env: ids, action mapping, episodes."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import hbmp_bench  # noqa: F401  (registers the ids)
from hbmp_bench.agents import load_agent
from hbmp_bench.planning.behaviors import BEHAVIORS
from hbmp_bench.errors import UnknownNameError
from hbmp_bench.transfer import SCENES, transfer_env_ids
from hbmp_bench.transfer.adapter import BEHAVIOR_TO_META, META_ACTIONS, META_TO_BEHAVIOR, to_behavior, to_meta_action
from hbmp_bench.transfer.env import HighwayTransferEnv


def test_action_mapping_round_trips_and_names_match_highway_env():
    from highway_env.envs.common.action import DiscreteMetaAction

    assert tuple(DiscreteMetaAction.ACTIONS_ALL[k] for k in range(5)) == META_ACTIONS
    for b in range(5):
        assert to_behavior(to_meta_action(b)) == b
        assert META_TO_BEHAVIOR[BEHAVIOR_TO_META[b]] == b
    for m in range(5):
        assert to_meta_action(to_behavior(m)) == m
    names = {BEHAVIORS[b]: META_ACTIONS[to_meta_action(b)] for b in range(5)}
    assert names == {"speed_up": "FASTER", "speed_down": "SLOWER", "change_left": "LANE_LEFT",
                     "change_right": "LANE_RIGHT", "keep": "IDLE"}
    with pytest.raises(ValueError):
        to_meta_action(5)
    with pytest.raises(ValueError):
        to_behavior(-1)


def test_ids_registered_on_import():
    assert transfer_env_ids() == tuple(f"hbmp_bench/HighwayTransfer-{s}-v0" for s in SCENES)
    assert all(i in gym.registry for i in transfer_env_ids())


@pytest.mark.parametrize("env_id", transfer_env_ids())
def test_check_env_every_id(env_id):
    env = gym.make(env_id)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_rgb_array_rendering():
    env = gym.make("hbmp_bench/HighwayTransfer-merge-v0", render_mode="rgb_array")
    env.reset(seed=0)
    image = env.render()
    assert image.ndim == 3 and image.shape[2] == 3 and image.dtype == np.uint8
    env.close()


def test_same_contract_as_the_sumo_env():
    from hbmp_bench.envs.behavior_env import BehaviorEnv

    sumo = BehaviorEnv(town="Town01", task="Straight")
    env = HighwayTransferEnv(scene="merge", observation="vehicle_centric")
    assert env.observation_space == sumo.observation_space
    assert env.action_space == sumo.action_space
    obs, info = env.reset(seed=0)
    for key in ("action_mask", "events", "infractions", "time_s", "route_completion", "episode_key", "scene"):
        assert key in info
    assert set(info["scene"]) >= {"speed_mps", "speed_limit_mps", "in_junction", "route_lane_offset",
                                  "stop_distance_m", "light", "goal_distance_m"}
    env.close()


def _alone_on_highway(lane_id: int):
    env = HighwayTransferEnv(scene="highway")
    env.reset(seed=1)
    hw = env.highway_env
    hw.road.vehicles = [hw.vehicle]
    lane = hw.road.network.get_lane(("0", "1", lane_id))
    s = lane.local_coordinates(hw.vehicle.position)[0]
    hw.vehicle.position = np.array(lane.position(s, 0.0))
    hw.vehicle.heading = lane.heading_at(s)
    hw.vehicle.on_state_update()
    hw.vehicle.target_lane_index = hw.vehicle.lane_index
    return env


@pytest.mark.parametrize("behavior, lane_after", [("change_left", 0), ("change_right", 2), ("keep", 1)])
def test_lane_change_behaviors_drive_to_the_lane_on_that_side(behavior, lane_after):
    env = _alone_on_highway(1)
    obs, info = env.step(4)[0], env.step(4)[4]
    np.testing.assert_array_equal(info["action_mask"], [1, 1, 1, 1, 1])
    obs, _, terminated, truncated, info = env.step(BEHAVIORS.index(behavior))
    assert env.ego.lane_index[2] == lane_after
    assert info["behavior_executed"] == behavior
    if behavior != "keep":  # a lane change runs until the ego has settled in the new lane
        assert 1.0 < info["duration_s"] <= env.config.lane_change_max_s
        s, lateral = env.ego.lane.local_coordinates(env.ego.position)
        assert abs(lateral) < env.config.settle_lateral_m
    else:
        assert info["duration_s"] == pytest.approx(0.1)
    env.close()


def test_infeasible_lane_change_is_executed_as_keep():
    env = _alone_on_highway(0)
    _, _, _, _, info = env.step(4)
    assert info["action_mask"][BEHAVIORS.index("change_left")] == 0
    _, _, _, _, info = env.step(BEHAVIORS.index("change_left"))
    assert info["behavior_executed"] == "keep" and env.ego.lane_index[2] == 0
    env.close()


def test_speed_behaviors_move_the_target_speed():
    env = _alone_on_highway(1)
    v0 = env.ego.target_speed
    env.step(BEHAVIORS.index("speed_up"))
    assert env.ego.target_speed > v0
    for _ in range(30):
        env.step(BEHAVIORS.index("speed_down"))
    assert env.ego.speed < v0 - 5.0
    env.close()


def _run(env, agent_name, seed):
    agent = load_agent(agent_name)
    obs, info = env.reset(seed=seed)
    agent.reset(info)
    trace = []
    while True:
        obs, reward, terminated, truncated, info = env.step(agent.act(obs, info))
        assert env.observation_space.contains(obs)
        trace.append((reward, float(obs["occupancy"].sum()), tuple(obs["road"])))
        if terminated or truncated:
            return trace, info


def test_short_expert_episode_records_the_outcome():
    env = HighwayTransferEnv(scene="merge")
    trace, info = _run(env, "expert", seed=0)
    record = info["hbmp_record"]
    assert record["suite"] == "highway-transfer" and record["town"] == record["task"] == "merge"
    assert record["fidelity"] == "highway-env:deformed"
    assert record["end_reason"] in ("goal", "collision", "timeout")
    assert record["success"] == (record["end_reason"] == "goal")
    assert record["decisions"] == len(trace) and record["distance_m"] > 0
    assert record["route_length_m"] == pytest.approx(370.0 - 30.0, abs=1.0)
    if record["success"]:
        assert trace[-1][0] == 100.0 and record["route_completion"] == 1.0
    env.close()


def test_same_seed_same_episode():
    env = HighwayTransferEnv(scene="intersection")
    a, info_a = _run(env, "random", seed=3)
    b, info_b = _run(env, "random", seed=3)
    assert a == b and info_a["hbmp_record"] == info_b["hbmp_record"]
    env.close()


def test_bad_input_is_a_clear_error():
    with pytest.raises(UnknownNameError, match="roundabout"):
        HighwayTransferEnv(scene="parking")
    with pytest.raises(ValueError, match="deformed"):
        HighwayTransferEnv(scene="highway", observation="birdseye")
    with pytest.raises(ValueError, match="decision_period_s"):
        HighwayTransferEnv(scene="highway", decision_period_s=0.3)
    env = HighwayTransferEnv(scene="highway")
    with pytest.raises(RuntimeError, match="reset"):
        env.step(0)
    env.reset(seed=0)
    for bad in (5, -1, 2.5, "left"):
        with pytest.raises(ValueError, match="action must be an int"):
            env.step(bad)
    env.close()


def test_a_scene_plays_the_same_whatever_ran_before_in_the_process():
    """highway-env's intersection scene changes its traffic model's class parameters; the adapter
    puts them back, so a seed gives the same episode before and after an intersection ran."""
    from hbmp_bench.transfer.evaluate import run_transfer_episodes

    def decisions(scene):
        return [(r.decisions, r.success, r.end_reason) for r in run_transfer_episodes("keep", scene, 2)]

    before = decisions("highway")
    run_transfer_episodes("keep", "intersection", 1)
    assert decisions("highway") == before
