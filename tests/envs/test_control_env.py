"""The flat baseline's control env: acceleration and steering at 10 Hz on real SUMO scenarios."""

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from hbmp_bench.envs.control_env import ControlEnv


@pytest.mark.slow
def test_passes_the_gymnasium_checker():
    env = ControlEnv(town="Town01", task="Straight", episode_index=0)
    check_env(env, skip_render_check=True)
    env.close()


@pytest.mark.slow
def test_throttle_and_lane_keeping_steer_move_the_ego_along_its_lane():
    env = ControlEnv(town="Town01", task="Straight", episode_index=0)
    obs, info = env.reset(seed=0)
    rewards = []
    for _ in range(40):  # 4 s of 70 % throttle, steering against the heading error
        heading_error = obs["road"][11] * np.pi / 2
        obs, reward, terminated, truncated, info = env.step(np.array([0.7, -2.0 * heading_error]))
        rewards.append((reward, info["reward_components"]))
        if terminated or truncated:
            break
    speed = info["scene"]["speed_mps"]
    reset_info = env.reset(seed=1)[1]
    env.close()
    assert speed > 4.0
    assert abs(obs["road"][10]) * 3.5 < 0.5  # within 0.5 m of the lane centre
    assert info["duration_s"] == pytest.approx(0.1)  # one control step per action
    assert "action_mask" not in info and "action_mask" not in reset_info, \
        "no behaviors to mask, on reset as on step (a training batch mixes both)"
    for r, parts in rewards:
        assert parts["r_k"] < 0.0 and r == pytest.approx(parts["r_k"] + parts["r_T"])


def test_bad_actions_and_fidelity_are_refused():
    with pytest.raises(ValueError, match="continuous"):
        ControlEnv(town="Town01", task="Straight", fidelity="event")
    env = ControlEnv(town="Town01", task="Straight", episode_index=0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="accel, steer"):
        env.step(np.array([0.1, 0.2, 0.3]))
    env.close()
