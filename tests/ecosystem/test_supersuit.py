"""PettingZoo's documented SB3 path: SuperSuit's ``pettingzoo_env_to_vec_env_v1`` and
``concat_vec_envs_v1`` (which copies the env) over the package's Box and fixed-agents wrappers, and
SB3's PPO with one policy shared by every agent (parameter sharing: ``test_recipes``). Every agent in
event fidelity, so every slot decides at every step (no transition with an ignored action)."""

import numpy as np
import pytest

ss = pytest.importorskip("supersuit", reason='the SuperSuit recipe needs: pip install "hbmp-bench[supersuit]"')
from hbmp_bench.envs import traffic_v0  # noqa: E402
from hbmp_bench.envs.ecosystem import BlackDeath, FlatObservations  # noqa: E402

CYCLES = 24

pytestmark = pytest.mark.slow


def make_env():
    return BlackDeath(FlatObservations(traffic_v0.parallel_env(
        town="Town01", task="NavigationDynamic", episode_index=0, controlled=2, fidelity="event",
        background_fidelity="event", max_cycles=CYCLES)))


def test_every_slot_decides_at_every_step_in_event_fidelity():
    env = traffic_v0.parallel_env(town="Town01", task="NavigationDynamic", episode_index=0, controlled=2,
                                  fidelity="event", background_fidelity="event", max_cycles=CYCLES)
    _, infos = env.reset(seed=0)
    while env.agents:
        assert all(infos[a]["decision_required"] for a in env.agents)
        _, _, _, _, infos = env.step({a: 0 for a in env.agents})
    env.close()


def test_supersuits_vector_env_resets_every_slot_together():
    vec = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(make_env()), 2, num_cpus=0, base_class="gymnasium")
    ends = []
    try:
        obs, _ = vec.reset(seed=0)
        assert obs.shape == (6, *vec.observation_space.shape)
        for _ in range(2 * CYCLES):
            obs, rewards, terms, truncs, infos = vec.step(np.array([vec.action_space.sample() for _ in range(6)]))
            ends.append(truncs | terms)
    finally:
        vec.close()
    assert np.array(ends).sum(axis=1).tolist() == [0] * (CYCLES - 1) + [6] + [0] * (CYCLES - 1) + [6]
    assert np.isfinite(obs).all()


def make_goal_env():
    """Three goal-directed agents (``ego``, ``ego1``, ``ego2``: each its own start, goal and route) and no
    circulating one."""
    return BlackDeath(FlatObservations(traffic_v0.parallel_env(
        town="Town02", task="NavigationDynamic", suite="hbmp", episode_index=0, agents=3, controlled="none",
        fidelity="event", max_cycles=CYCLES)))


def test_goal_directed_agents_vectorise_and_end_together():
    vec = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(make_goal_env()), 2, num_cpus=0,
                                base_class="gymnasium")
    ends = []
    try:
        obs, _ = vec.reset(seed=0)
        assert obs.shape == (6, *vec.observation_space.shape)
        for _ in range(CYCLES):
            obs, rewards, terms, truncs, infos = vec.step(np.array([vec.action_space.sample() for _ in range(6)]))
            ends.append(truncs | terms)
            assert np.isfinite(rewards).all()
    finally:
        vec.close()
    assert np.array(ends).sum(axis=1).tolist() == [0] * (CYCLES - 1) + [6]
    assert np.isfinite(obs).all()
