"""The ecosystem's conventions at the env's door, without a trainer: Gymnasium's and PettingZoo's
checkers, render modes that draw only when asked, the record under its own info key, a step cap a
trainer sees, copies of a reset env, the wrappers for SuperSuit and RLlib, no leaked file."""

import copy
import gc
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test

from hbmp_bench.envs import traffic_v0
from hbmp_bench.envs.ecosystem import BlackDeath, DecisionsOnly, FlatObservations
from hbmp_bench.envs.registration import RECORD_KEY

ENV_ID = "hbmp_bench:hbmp_bench/Town01-Straight-v0"
MULTI = dict(town="Town01", task="NavigationDynamic", episode_index=0, controlled=2)

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("render_mode", ["rgb_array", "rgb_array_list"])
def test_gymnasium_checker_with_each_render_mode(render_mode):
    env = gym.make(ENV_ID, fidelity="event", episode_index=0, render_mode=render_mode)
    check_env(env.unwrapped)
    env.close()


def test_the_record_has_its_own_key_and_survives_the_ecosystems_statistics():
    env = gym.wrappers.RecordEpisodeStatistics(gym.make(ENV_ID, fidelity="event", episode_index=0, max_cycles=20))
    env.reset(seed=0)
    for steps in range(1, 100):
        _, _, term, trunc, info = env.step(4)
        if term or trunc:
            break
    env.close()
    assert (steps, term, trunc) == (20, False, True), "max_cycles truncates at its step"
    assert set(info["episode"]) == {"r", "l", "t"} and info["episode"]["l"] == 20
    record = info[RECORD_KEY]
    assert record["end_reason"] == "decision_cap" and record["decisions"] == 20 and not record["success"]


def test_time_limit_of_gymnasium_truncates_too():
    env = gym.make(ENV_ID, fidelity="event", episode_index=0, max_episode_steps=15)
    env.reset(seed=0)
    ends = [env.step(4)[3] for _ in range(15)]
    env.close()
    assert ends == [False] * 14 + [True]


def test_a_reset_env_pickles_and_deep_copies_as_a_fresh_one():
    env = traffic_v0.parallel_env(**MULTI, fidelity="event")
    obs, _ = env.reset(seed=3)
    env.step({a: 4 for a in env.agents})
    copies = [pickle.loads(pickle.dumps(env)), copy.deepcopy(env), copy.deepcopy(FlatObservations(env))]
    for other in copies:
        assert other.agents == [] and other.possible_agents == env.possible_agents
        again, _ = other.reset(seed=3)
        again = {a: o for a, o in again.items()} if isinstance(other, traffic_v0.TrafficParallelEnv) else None
        if again is not None:
            assert all(np.array_equal(again[a]["road"], obs[a]["road"]) for a in obs)
            assert all(np.array_equal(again[a]["occupancy"], obs[a]["occupancy"]) for a in obs)
        other.close()
    env.close()


def test_the_single_ego_views_copy_after_reset():
    for env in (gym.make(ENV_ID, fidelity="event", episode_index=0),
                traffic_v0.ego_env("keep", **MULTI, fidelity="event")):
        obs, _ = env.reset(seed=2)
        env.step(4)
        other = copy.deepcopy(env)
        again, _ = other.reset(seed=2)
        assert np.array_equal(again["road"], obs["road"]) and np.array_equal(again["occupancy"], obs["occupancy"])
        other.close()
        env.close()


def test_the_flat_wrapper_passes_pettingzoos_api_test():
    env = FlatObservations(traffic_v0.parallel_env(**MULTI, fidelity="event"))
    parallel_api_test(env, num_cycles=30)
    env.close()


def test_black_death_keeps_every_agent_until_all_have_ended():
    env = BlackDeath(FlatObservations(traffic_v0.parallel_env(**MULTI, fidelity="event", max_cycles=25)))
    obs, _ = env.reset(seed=0)
    assert set(obs) == set(env.possible_agents)
    for step in range(1, 100):
        obs, rewards, terms, truncs, infos = env.step({a: 4 for a in env.possible_agents})
        assert set(obs) == set(rewards) == set(terms) == set(env.possible_agents)
        assert all(o.shape == env.observation_space(a).shape for a, o in obs.items())
        done = [terms[a] or truncs[a] for a in env.possible_agents]
        assert all(done) or not any(done), "every slot ends together"
        if all(done):
            break
    env.close()
    assert step == 25 and env.agents == []


def test_decisions_only_leaves_out_agents_with_nothing_to_decide_and_keeps_their_rewards():
    """Continuous ego (behaviors of 1-8 s), event background: the ego is left out of the dicts while its
    behavior runs, and its rewards meanwhile arrive, summed, with its next observation."""
    plain = traffic_v0.parallel_env(**MULTI, max_cycles=40)
    wrapped = DecisionsOnly(traffic_v0.parallel_env(**MULTI, max_cycles=40))
    obs_p, info_p = plain.reset(seed=1)
    obs_w, _ = wrapped.reset(seed=1)
    totals_p, totals_w, ego_left_out = {}, {}, 0
    while plain.agents:
        actions = {a: 0 for a in plain.agents if info_p[a]["decision_required"]}
        assert set(actions) == set(obs_w), "the wrapper observes exactly the agents that must act"
        obs_p, rew_p, term_p, trunc_p, info_p = plain.step(actions)
        obs_w, rew_w, term_w, trunc_w, info_w = wrapped.step(actions)
        ego_left_out += "ego" not in obs_w
        assert all(info_w[a]["decision_required"] or term_w.get(a) or trunc_w.get(a) for a in obs_w)
        for a, r in rew_p.items():
            totals_p[a] = totals_p.get(a, 0.0) + r
        for a, r in rew_w.items():
            totals_w[a] = totals_w.get(a, 0.0) + r
    plain.close()
    wrapped.close()
    assert ego_left_out > 0
    assert totals_w == pytest.approx(totals_p), "no reward is lost or moved to another agent"


def test_traci_runs_leave_no_open_file():
    """The second simulation in a process runs over TraCI; its SUMO log must be closed by us."""
    first = traffic_v0.parallel_env(**MULTI, fidelity="event")
    second = traffic_v0.parallel_env(**MULTI, fidelity="event")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ResourceWarning)
        first.reset(seed=0)
        second.reset(seed=0)
        second.step({a: 4 for a in second.agents})
        second.close()
        first.close()
        gc.collect()
    leaks = [w for w in caught if issubclass(w.category, ResourceWarning)]
    assert leaks == [], [str(w.message) for w in leaks]
