"""The flat baseline's control env: acceleration and steering at 10 Hz on real SUMO scenarios."""

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from hbmp_bench.envs.control_env import ControlEnv
from hbmp_bench.envs.world import EGO_ID


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


@pytest.mark.slow
def test_the_carla_reward_pays_route_progress_and_speed_gained_and_logs_r_T():
    """``reward="carla"``: the step rewards sum to the route progress [m] (the episode scorer's) plus 0.05 per km/h
    of speed gained since the start, as CARLA's RL baseline is paid."""
    env = ControlEnv(town="Town01", task="Straight", episode_index=0, reward="carla")
    obs, info = env.reset(seed=0)
    speed0, total, steps = info["scene"]["speed_mps"], 0.0, []
    for _ in range(60):
        heading_error = obs["road"][11] * np.pi / 2
        obs, reward, terminated, truncated, info = env.step(np.array([0.7, -2.0 * heading_error - obs["road"][10]]))
        total += reward
        steps.append(info["reward_components"])
        assert not (terminated or truncated)
    progress_m = env.world.vehicles[EGO_ID].route.score.progress_m
    env.close()
    speed_gain_kmh = 3.6 * (info["scene"]["speed_mps"] - speed0)
    assert progress_m > 10.0 and speed_gain_kmh > 10.0
    assert total == pytest.approx(progress_m + 0.05 * speed_gain_kmh, abs=1e-6)
    assert all(parts["r_T"] == 0.0 and parts["r_k"] == 0.0 for parts in steps)


def test_the_carla_reward_prices_each_event_as_a_whole_overlap():
    from hbmp_bench.metrics.detectors import StepEvents
    from hbmp_bench.metrics.episode import carla_rl_reward

    assert carla_rl_reward(2.0, 1.0, StepEvents()) == pytest.approx(2.0 + 0.05 * 3.6)
    assert carla_rl_reward(0.0, 0.0, StepEvents(off_road=1, wrong_lane=1)) == pytest.approx(-4.0)


def test_bad_actions_and_fidelity_are_refused():
    with pytest.raises(ValueError, match="continuous"):
        ControlEnv(town="Town01", task="Straight", fidelity="event")
    env = ControlEnv(town="Town01", task="Straight", episode_index=0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="accel, steer"):
        env.step(np.array([0.1, 0.2, 0.3]))
    env.close()
