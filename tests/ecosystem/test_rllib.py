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
