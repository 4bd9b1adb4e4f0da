"""Stable-Baselines3's PPO trains on the gymnasium env as SB3's docs say to build it: ``make_vec_env``
(its default ``render_mode="rgb_array"`` and ``Monitor``; with ``SubprocVecEnv``: ``test_recipes``), and without ``Monitor``
(bare, or Gymnasium's ``RecordEpisodeStatistics``). A few hundred real steps each; episodes end
(``max_cycles``), SB3's statistics and the package's record both arrive."""

import gymnasium as gym
import numpy as np
import pytest

sb3 = pytest.importorskip("stable_baselines3", reason='the SB3 recipe needs: pip install "hbmp-bench[sb3]"')
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402

from hbmp_bench.envs.registration import RECORD_KEY  # noqa: E402

ENV_ID = "hbmp_bench:hbmp_bench/Town01-Straight-v0"  # "module:id": a SubprocVecEnv worker imports the package
ENV_KWARGS = dict(fidelity="event", max_cycles=40)
STEPS = 256

pytestmark = pytest.mark.slow


class Records(BaseCallback):
    """The package's records seen at episode ends."""

    def __init__(self):
        super().__init__()
        self.records = []

    def _on_step(self) -> bool:
        for done, info in zip(self.locals["dones"], self.locals["infos"]):
            if done:
                self.records.append(info[RECORD_KEY])
        return True


def _vec_env(kind: str):
    if kind == "make_vec_env":  # SB3's defaults: DummyVecEnv, Monitor, render_mode="rgb_array"
        return make_vec_env(ENV_ID, n_envs=2, seed=0, env_kwargs=ENV_KWARGS)
    if kind == "no-monitor":
        return DummyVecEnv([lambda: gym.make(ENV_ID, **ENV_KWARGS)])
    if kind == "record-episode-statistics":
        return DummyVecEnv([lambda: gym.wrappers.RecordEpisodeStatistics(gym.make(ENV_ID, **ENV_KWARGS))])
    raise ValueError(kind)


@pytest.mark.parametrize("kind", ["make_vec_env", "no-monitor", "record-episode-statistics"])  # SubprocVecEnv: test_recipes
def test_ppo_trains_on_the_gymnasium_env(kind):
    vec = _vec_env(kind)
    try:
        if kind == "make_vec_env":
            assert vec.get_attr("render_mode") == ["rgb_array"] * 2, "SB3's default render mode is in play"
        model = PPO("MultiInputPolicy", vec, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu",
                    policy_kwargs=dict(normalize_images=False))
        from stable_baselines3.common.torch_layers import NatureCNN

        assert isinstance(model.policy.features_extractor.extractors["occupancy"], NatureCNN), \
            "normalize_images=False: SB3 reads the float32 M_t as an image, not a flat vector"
        before = [p.detach().clone() for p in model.policy.parameters()]
        records = Records()
        model.learn(STEPS, callback=records)
    finally:
        vec.close()
    assert model.num_timesteps >= STEPS
    assert any(not np.allclose(b.numpy(), p.detach().numpy()) for b, p in zip(before, model.policy.parameters()))
    assert len(records.records) >= STEPS // ENV_KWARGS["max_cycles"] - 1
    assert all(r["end_reason"] in ("decision_cap", "goal", "violation", "collision", "timeout", "left_network")
               and "success" in r for r in records.records)
    if kind == "no-monitor":
        assert len(model.ep_info_buffer) == 0  # no KeyError: "episode" is SB3's key, the package's is its own
    else:
        assert sorted(e["l"] for e in model.ep_info_buffer) == sorted(r["decisions"] for r in records.records)
