"""The PettingZoo traffic env: API conformance, seeding, decision timing, bad input."""

import numpy as np
import pytest
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test

from hbmp_bench.envs import BehaviorEnv, traffic_v0
from hbmp_bench.errors import UnknownNameError

SMALL = dict(town="Town01", task="NavigationDynamic", episode_index=0, controlled=3)
SPEED_UP, SPEED_DOWN, KEEP = 0, 1, 4


FIDELITIES = ("continuous", "event")


@pytest.mark.slow
@pytest.mark.parametrize("fidelity", FIDELITIES)
def test_parallel_api(fidelity):
    env = traffic_v0.parallel_env(**SMALL, ego_fidelity=fidelity, background_fidelity=fidelity)
    parallel_api_test(env, num_cycles=40)
    env.close()


@pytest.mark.slow
@pytest.mark.parametrize("fidelity", FIDELITIES)
def test_parallel_seed(fidelity):
    """Two envs stepped in turn in this process (the second one runs SUMO over TraCI)."""
    parallel_seed_test(lambda: traffic_v0.parallel_env(**SMALL, ego_fidelity=fidelity, background_fidelity=fidelity),
                       num_cycles=20)


@pytest.mark.slow
@pytest.mark.parametrize("fidelity", FIDELITIES)
def test_aec_api(fidelity):
    env = traffic_v0.env(**SMALL, ego_fidelity=fidelity, background_fidelity=fidelity)
    api_test(env, num_cycles=15)
    env.close()


@pytest.mark.slow
def test_api_tests_with_the_default_settings():
    """The README's settings: Town01 NavigationDynamic, every background vehicle an agent, ego continuous."""
    env = traffic_v0.parallel_env()
    parallel_api_test(env, num_cycles=30)
    env.close()
    aec = traffic_v0.env()
    api_test(aec, num_cycles=10)
    aec.close()


@pytest.mark.slow
def test_busy_agents_do_not_decide_and_their_actions_are_ignored():
    env = traffic_v0.parallel_env(**SMALL)  # ego continuous (behaviors >= 1 s), background event (0.1 s)
    obs, infos = env.reset(seed=1)
    assert all(infos[a]["decision_required"] for a in env.agents)
    obs, rewards, term, trunc, infos = env.step({a: SPEED_UP for a in env.agents})
    assert not infos["ego"]["decision_required"]
    assert all(infos[a]["decision_required"] for a in env.agents if a != "ego")
    assert all(infos[a]["behavior"] == "speed_up" for a in env.agents if a != "ego")
    steps = 1
    while not infos["ego"]["decision_required"]:
        # speed_down for the busy ego is ignored; its missing action is fine too
        actions = {a: KEEP for a in env.agents if a != "ego"}
        if steps % 2:
            actions["ego"] = SPEED_DOWN
        obs, rewards, term, trunc, infos = env.step(actions)
        steps += 1
        assert steps < 200
    assert infos["ego"]["behavior"] == "speed_up"
    assert infos["ego"]["duration_s"] == pytest.approx(steps * 0.1, abs=1e-6)
    assert steps >= 2
    env.close()


def test_bad_input_names_live_agents():
    env = traffic_v0.parallel_env(**SMALL, ego_fidelity="event")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="live agents"):
        env.step({a: KEEP for a in [*env.agents, "bg99"]})
    with pytest.raises(ValueError, match="need a decision"):
        env.step({"ego": KEEP})
    with pytest.raises(ValueError, match=r"action of bg0"):
        env.step({a: 7 if a == "bg0" else KEEP for a in env.agents})
    env.close()


@pytest.mark.parametrize("controlled", ["some", -1, 10_000, True])
def test_bad_controlled_value(controlled):
    with pytest.raises(ValueError, match="controlled"):
        traffic_v0.parallel_env(town="Town01", controlled=controlled)


def test_agents_and_spaces():
    env = traffic_v0.parallel_env(town="Town01", task="NavigationDynamic", controlled="all")
    n = env.episodes[0].traffic.vehicles
    assert env.possible_agents == ["ego", *(f"bg{k}" for k in range(n))]
    assert env.observation_space("bg0") is env.observation_space("ego")
    assert traffic_v0.parallel_env(town="Town01", controlled="none").possible_agents == ["ego"]


@pytest.mark.slow
def test_no_controlled_vehicle_matches_the_single_ego_env():
    """The gymnasium env and this one run the same world: identical ego trajectories."""
    single = BehaviorEnv(town="Town01", task="NavigationDynamic", episode_index=0, fidelity="event")
    obs, _ = single.reset(seed=5)
    trace_single = [obs["road"]]
    for k in range(30):
        obs, *_ = single.step((SPEED_UP, KEEP)[k % 2])
        trace_single.append(obs["road"])
    single.close()
    multi = traffic_v0.parallel_env(town="Town01", task="NavigationDynamic", episode_index=0, controlled="none",
                                    ego_fidelity="event")
    obs, _ = multi.reset(seed=5)
    trace_multi = [obs["ego"]["road"]]
    for k in range(30):
        obs, *_ = multi.step({"ego": (SPEED_UP, KEEP)[k % 2]})
        trace_multi.append(obs["ego"]["road"])
    multi.close()
    np.testing.assert_array_equal(np.array(trace_single), np.array(trace_multi))


@pytest.mark.slow
def test_background_agents_keep_circulating_and_see_each_other():
    env = traffic_v0.parallel_env(**SMALL, ego_fidelity="event")
    obs, infos = env.reset(seed=2)
    seen_others = False
    for _ in range(150):
        obs, rewards, term, trunc, infos = env.step({a: SPEED_UP if k % 2 else KEEP for k, a in enumerate(env.agents)})
        seen_others |= any(obs[a]["occupancy"].any() for a in env.agents)
        assert set(env.agents) == {a for a in env.possible_agents if not (term.get(a) or trunc.get(a))} or not env.agents
        if not env.agents:
            break
    assert seen_others
    assert any(infos[a]["scene"]["speed_mps"] > 1.0 for a in env.agents if a != "ego")
    env.close()


@pytest.mark.slow
def test_same_seed_same_multi_agent_episode():
    """Stronger than ``parallel_seed_test`` (which stops after one step): 40 steps, every agent."""
    env = traffic_v0.parallel_env(**SMALL, ego_fidelity="event")

    def rollout():
        obs, _ = env.reset(seed=7)
        trace = []
        for k in range(40):
            obs, rewards, *_ = env.step({a: (SPEED_UP, KEEP, SPEED_DOWN)[(k + j) % 3] for j, a in enumerate(env.agents)})
            trace.append(np.concatenate([np.r_[obs[a]["road"], obs[a]["occupancy"].sum(), rewards[a]] for a in sorted(obs)]))
        return np.array(trace)

    first, second = rollout(), rollout()
    env.close()
    np.testing.assert_array_equal(first, second)


def test_render_shows_the_scene_after_a_step():
    env = traffic_v0.parallel_env(town="Town01", task="NavigationDynamic", episode_index=0, controlled=2,
                                  ego_fidelity="event", render_mode="rgb_array")
    obs, infos = env.reset(seed=0)
    env.step({a: 4 for a in env.agents if infos[a]["decision_required"]})
    image = env.render()
    env.close()
    assert image.shape == (400, 400, 3) and image.dtype == np.uint8
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 10  # a drawn scene, not a blank canvas
    with pytest.raises(ValueError, match="render_mode"):
        traffic_v0.parallel_env(render_mode="human")


def test_ego_env_drives_background_agents_with_a_policy():
    """The single-ego view: the ego's actions go in, background agents get the expert's."""
    env = traffic_v0.ego_env("expert", town="Town01", task="NavigationDynamic", episode_index=0, controlled=3,
                             ego_fidelity="event")
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    start = env.parallel.world.sim.time
    for _ in range(20):
        obs, reward, terminated, truncated, info = env.step(0)
        assert env.observation_space.contains(obs)
        if terminated or truncated:
            break
    elapsed = env.parallel.world.sim.time - start
    speeds = [env._infos[a]["scene"]["speed_mps"] for a in ("bg0", "bg1", "bg2")]
    env.close()
    assert elapsed >= 1.9  # 20 ego decisions of 0.1 s
    assert max(speeds) > 1.0  # the expert drove the background agents off from standstill
    with pytest.raises(UnknownNameError):
        traffic_v0.ego_env("no-such-agent")
