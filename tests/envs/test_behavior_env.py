import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import hbmp_bench  # noqa: F401  (registers the ids)
from hbmp_bench.agents import agent_env_kwargs, load_agent
from hbmp_bench.envs import env_ids, make
from hbmp_bench.errors import UnknownNameError
from hbmp_bench.metrics.episode import TERMINAL_REWARD


def _checked_ids() -> list[str]:
    """Every id of a task category, and of each scenario type the first town that hosts it (the same env
    class: a type differs from another in its episodes and actors, which the scenario tests check)."""
    from hbmp_bench.envs.registration import SCENARIO_TOWNS

    firsts = {f"hbmp_bench/{towns[0]}-{name}-v0" for name, towns in SCENARIO_TOWNS.items()}
    return [i for i in env_ids() if not any(f"-{name}-" in i for name in SCENARIO_TOWNS) or i in firsts]


@pytest.mark.slow
@pytest.mark.parametrize("env_id", _checked_ids())
def test_check_env_every_id(env_id):
    """gymnasium's checker with its defaults (its render check makes a second env of the id in
    this process: that one runs SUMO over TraCI)."""
    env = gym.make(env_id)
    check_env(env.unwrapped)
    env.close()


def test_make_through_module_prefix():
    env = gym.make("hbmp_bench:hbmp_bench/Town02-Straight-v0")
    assert env.action_space.n == 5
    env.close()


def test_unknown_env_id_lists_valid_ones():
    with pytest.raises(UnknownNameError, match="Town01-Straight-v0"):
        make("hbmp_bench/Town07-Straight-v0")


def _rollout(env, seed, agent="expert", steps=300):
    agent = load_agent(agent)
    obs, info = env.reset(seed=seed)
    agent.reset(info)
    trace = [obs["road"].copy(), obs["occupancy"].sum()]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(agent.act(obs, info))
        trace.append((obs["road"].copy(), float(obs["occupancy"].sum()), reward, info["time_s"]))
        if terminated or truncated:
            break
    return trace


def test_same_seed_same_episode_with_traffic():
    env = gym.make("hbmp_bench/Town01-NavigationDynamic-v0").unwrapped
    a = _rollout(env, seed=3)
    b = _rollout(env, seed=3)
    env.close()
    assert len(a) == len(b)
    for x, y in zip(a[2:], b[2:]):
        np.testing.assert_array_equal(x[0], y[0])
        assert x[1:] == y[1:]


def test_out_of_range_action_is_a_clear_error():
    env = gym.make("hbmp_bench/Town02-Straight-v0", episode_index=0).unwrapped
    env.reset(seed=0)
    for bad in (5, -1, 2.5, "left", np.array(True)):
        with pytest.raises(ValueError, match="action must be an int"):
            env.step(bad)
    for bad in (True, False, np.True_):  # a bool is an int to Python, and to Discrete.contains, but no behavior
        with pytest.raises(ValueError, match=r"action must be an int in \[0, 5\) .*got bool") as err:
            env.step(bad)
        assert "\n" not in str(err.value)
    obs, *_ = env.step(np.int64(4))  # numpy ints stay valid
    env.close()


@pytest.mark.parametrize("env_id", ["hbmp_bench/Town01-Straight-v0", "hbmp_bench/Training-v0"])
def test_unknown_density_fails_at_make_before_sumo_starts(env_id, monkeypatch):
    from hbmp_bench.sim.sumo import SumoSim

    def no_sumo(*args, **kwargs):
        raise AssertionError("SUMO started")

    monkeypatch.setattr(SumoSim, "start", no_sumo)
    with pytest.raises(ValueError, match="unknown density 'x'; valid: corl, dense, empty, regular") as err:
        gym.make(env_id, density="x")
    assert "\n" not in str(err.value)
    env = gym.make(env_id, density="dense")  # a valid one is accepted (and nothing starts either)
    assert env.unwrapped.traffic.vehicles > 0
    env.close()


def test_infeasible_lane_change_becomes_keep_and_mask_says_so():
    env = gym.make("hbmp_bench/Town01-Straight-v0", episode_index=0).unwrapped  # one lane per direction
    obs, info = env.reset(seed=0)
    assert info["action_mask"].tolist() == [1, 1, 0, 0, 1]
    _, _, _, _, info = env.step(2)
    assert info["behavior_executed"] == "keep"
    env.close()


@pytest.mark.slow
def test_expert_clean_success_on_a_static_episode():
    agent = load_agent("expert")
    env = gym.make("hbmp_bench/Town01-OneTurn-v0", episode_index=0, **agent_env_kwargs(agent)).unwrapped
    obs, info = env.reset(seed=0)
    agent.reset(info)
    while True:
        obs, reward, terminated, truncated, info = env.step(agent.act(obs, info))
        if terminated or truncated:
            break
    record = info["hbmp_record"]
    env.close()
    parts = info["reward_components"]
    assert record["success"] and parts["r_T"] == 100.0
    assert reward == pytest.approx(parts["r_T"] + parts["r_k"]) and parts["r_k"] <= 0.0
    assert record["collision_vehicle"] + record["collision_pedestrian"] + record["wrong_lane"] + record["red_light"] + record["off_road"] == 0
    assert record["route_completion"] == 1.0


def test_occupancy_marks_background_vehicles():
    agent = load_agent("expert")
    env = gym.make("hbmp_bench/Town01-NavigationDynamic-v0", episode_index=0, **agent_env_kwargs(agent)).unwrapped
    obs, info = env.reset(seed=0)
    agent.reset(info)
    seen = 0.0
    for _ in range(600):
        obs, _, terminated, truncated, info = env.step(agent.act(obs, info))
        seen = max(seen, float(obs["occupancy"].sum()))
        if terminated or truncated:
            break
    env.close()
    assert seen > 0


def test_leaving_the_network_before_the_goal_pays_the_overtime_penalty():
    """Ending off the network (route end in another lane than the goal's, or off the map) is a failure, not a
    free way out: r_T is the overtime's -50, as a timeout's."""
    env = gym.make("hbmp_bench/Town01-Straight-v0", episode_index=0, fidelity="event").unwrapped
    env.reset(seed=0)
    env.step(0)
    env.world.ego.driver.off_map = True  # what the driver reports when SUMO cannot place the car
    _, reward, terminated, truncated, info = env.step(0)
    env.close()
    assert terminated and not truncated and info["hbmp_record"]["end_reason"] == "left_network"
    assert info["reward_components"]["r_T"] == TERMINAL_REWARD["timeout"] == -50.0
    assert not info["hbmp_record"]["success"]


def test_an_episode_a_violation_ends_pays_the_overtime_penalty_too():
    """Under the paper's protocol a red light ends the episode: it pays −10 and the overtime's −50 (with −10
    alone, running a light would be the cheap way out of an episode that might time out); under CoRL2017 the
    episode goes on and the red light pays −10. Town01 Navigation 3, speed_up only, runs a red after 8 s."""
    rewards = {}
    for suite in ("hbmp", "corl2017"):
        env = gym.make("hbmp_bench/Town01-Navigation-v0", suite=suite, episode_index=3, fidelity="event").unwrapped
        env.reset(seed=0)
        for _ in range(400):
            _, _, terminated, truncated, info = env.step(0)
            if info["reward_components"]["r_T"] < 0 or terminated or truncated:
                break
        env.close()
        rewards[suite] = (terminated, info["reward_components"]["r_T"])
    assert rewards["hbmp"] == (True, TERMINAL_REWARD["red_light"] + TERMINAL_REWARD["timeout"])
    assert rewards["corl2017"] == (False, TERMINAL_REWARD["red_light"])
