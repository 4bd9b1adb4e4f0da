"""The package's RLlib env: RLlib's ``ParallelPettingZooEnv`` with Box observations, only the agents
that must decide in each dict, an ``__all__`` that ends the episode when no agent is left, and a
``render()`` that works (RLlib's PPO for one iteration with a shared policy: ``test_recipes``)."""

import numpy as np
import pytest

pytest.importorskip("ray.rllib", reason='the RLlib recipe needs: pip install "hbmp-bench[rllib]"')

from hbmp_bench.envs.rllib import rllib_env  # noqa: E402

CONFIG = dict(town="Town01", task="NavigationDynamic", episode_index=0, controlled=2, max_cycles=30)

pytestmark = pytest.mark.slow


def test_the_rllib_env_ends_episodes_and_renders():
    env = rllib_env(dict(CONFIG, render_mode="rgb_array"))
    obs, _ = env.reset(seed=0)
    assert set(obs) == {"ego", "bg0", "bg1"} and all(isinstance(o, np.ndarray) for o in obs.values())
    image = env.render()
    assert image.shape == (400, 400, 3)
    steps, ego_left_out = 0, 0
    while True:
        obs, rewards, terms, truncs, _ = env.step({a: 4 for a in obs})
        steps += 1
        ego_left_out += "ego" not in obs
        assert set(rewards) == set(obs)
        if terms["__all__"] or truncs["__all__"]:
            break
    env.close()
    assert steps == 30 and truncs["__all__"] and not terms["__all__"] and ego_left_out > 0


def test_goal_directed_agents_end_the_episode_in_rllib():
    """Three goal-directed agents driven by the expert to their goals: the last one's arrival terminates
    ``__all__`` (none of them left over, no circulating agent)."""
    from hbmp_bench.agents import load_agent
    from hbmp_bench.envs.traffic_v0 import TrafficParallelEnv

    config = dict(town="Town02", task="NavigationDynamic", suite="hbmp", episode_index=0, agents=3,
                  controlled="none", fidelity="event", density="empty", privileged=True)
    env = rllib_env(config)
    shadow = TrafficParallelEnv(**config)  # the same episode, for the expert's Dict observations and infos
    obs, _ = env.reset(seed=0)
    shadow_obs, shadow_infos = shadow.reset(seed=0)
    experts = {a: load_agent("expert") for a in shadow.agents}
    for a in shadow.agents:
        experts[a].reset(shadow_infos[a])
    assert set(obs) == {"ego", "ego1", "ego2"}
    ended = set()
    for _ in range(3000):
        actions = {a: experts[a].act(shadow_obs[a], shadow_infos[a]) for a in obs if a not in ended}
        obs, _, terms, truncs, infos = env.step(actions)
        shadow_obs, *_, shadow_infos = shadow.step(actions)
        ended |= {a for a in terms if a != "__all__" and (terms[a] or truncs[a])}
        if terms["__all__"] or truncs["__all__"]:
            break
    env.close()
    shadow.close()
    assert terms["__all__"] and not truncs["__all__"] and ended == {"ego", "ego1", "ego2"}
