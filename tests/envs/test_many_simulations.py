"""Several simulations in one process (the first on libsumo, the others over TraCI), and resets
that never crash whatever ran before."""

import gymnasium as gym
import numpy as np
import pytest

import hbmp_bench  # noqa: F401  (registers the ids)
from hbmp_bench.envs import BehaviorEnv, traffic_v0
from hbmp_bench.maps import net_path
from hbmp_bench.sim import SumoSim

MIXES = [("continuous", "event"), ("event", "continuous"), ("continuous", "continuous"), ("event", "event")]


def _episode_trace(env: BehaviorEnv, seed: int, steps: int) -> np.ndarray:
    obs, _ = env.reset(seed=seed, options={"episode_index": 0})
    rows = [obs["road"]]
    for k in range(steps):
        obs, reward, term, trunc, _ = env.step((0, 4, 1)[k % 3])
        rows.append(np.r_[obs["road"], reward])
        if term or trunc:
            break
    return np.concatenate(rows)


def test_second_simulation_runs_over_traci_and_gives_the_same_episode():
    first = BehaviorEnv(town="Town01", task="Straight", fidelity="continuous")
    second = BehaviorEnv(town="Town01", task="Straight", fidelity="continuous")
    trace_first = _episode_trace(first, seed=3, steps=6)
    trace_second = _episode_trace(second, seed=3, steps=6)
    assert first.world.sim.uses_libsumo and not second.world.sim.uses_libsumo
    np.testing.assert_array_equal(trace_first, trace_second)
    first.close()
    trace_after = _episode_trace(second, seed=3, steps=6)  # libsumo is free again: the next start takes it
    assert second.world.sim.uses_libsumo
    np.testing.assert_array_equal(trace_first, trace_after)
    second.close()


def test_close_is_idempotent_and_frees_libsumo():
    sim = SumoSim(net_path("Town01"))
    sim.start(seed=0)
    assert sim.running and sim.uses_libsumo
    sim.close()
    sim.close()
    assert not sim.running
    other = SumoSim(net_path("Town01"))
    other.start(seed=0)
    assert other.uses_libsumo
    other.close()


def test_reset_after_a_step_with_a_continuous_ego_and_agents():
    """The README's settings, reset after one step: a segmentation fault in libsumo before (a pose
    pushed with moveToXY outlived the closed simulation)."""
    env = traffic_v0.parallel_env(town="Town01", task="NavigationDynamic", controlled=1)
    obs, infos = env.reset(seed=0)
    env.step({a: 4 for a in env.agents if infos[a]["decision_required"]})
    obs, infos = env.reset()
    assert env.agents == ["ego", "bg0"] and all(infos[a]["decision_required"] for a in env.agents)
    env.close()


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["sync", "async"])
def test_make_vec(mode):
    envs = gym.make_vec("hbmp_bench/Town01-Straight-v0", num_envs=2, vectorization_mode=mode)
    obs, infos = envs.reset(seed=0)
    assert obs["road"].shape == (2, *envs.single_observation_space["road"].shape)
    for _ in range(3):
        obs, rewards, terms, truncs, infos = envs.step(envs.action_space.sample())
    assert rewards.shape == (2,)
    envs.close()


@pytest.mark.slow
def test_reset_soak():
    """1000 resets after a random number of steps (0-3) with random actions, every mix of
    continuous and event agents; short episodes keep it to a couple of minutes."""
    rng = np.random.default_rng(0)
    env, steps = None, 0
    for k in range(1000):
        if k % 50 == 0:
            if env is not None:
                env.close()
            ego, background = MIXES[(k // 50) % len(MIXES)]
            env = traffic_v0.parallel_env(town="Town01", task="NavigationDynamic", controlled=2,
                                          ego_fidelity=ego, background_fidelity=background)
        obs, infos = env.reset(seed=int(rng.integers(2**31)))
        assert env.agents == env.possible_agents
        for _ in range(int(rng.integers(0, 4))):
            if not env.agents:
                break
            actions = {a: int(rng.integers(5)) for a in env.agents if infos[a]["decision_required"]}
            obs, rewards, terms, truncs, infos = env.step(actions)
            steps += 1
    env.close()
    assert steps > 1000
