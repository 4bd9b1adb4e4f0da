"""The rsl-rl VecEnv adapter with real SUMO workers: groups, shapes, dtypes, dones, time_outs, auto-reset."""

import os
import signal

import pytest
import torch
from tensordict import TensorDict

from hbmp_bench.training.vec_env import SubprocVecEnv, WorkerError
from hbmp_bench.training.worker import WorkerEnvConfig, training_reward

SHORT = "hbmp_bench/Town02-Straight-v0"
KEEP, EVENT = 4, {"fidelity": "event"}


def _check_obs(obs, n):
    assert isinstance(obs, TensorDict) and obs.batch_size == torch.Size([n])
    assert obs["occupancy"].shape == (n, 1, 64, 36) and obs["occupancy"].dtype == torch.float32
    assert obs["road"].shape == (n, 10) and obs["road"].dtype == torch.float32
    assert obs["action_mask"].shape == (n, 5)
    assert set(obs["occupancy"].unique().tolist()) <= {0.0, 1.0}


@pytest.mark.slow
def test_standing_still_times_out_and_auto_resets():
    """``keep`` from standstill never reaches the goal: every episode ends by the CoRL timeout, which
    must show up as done + time_out, and the env must continue with a fresh episode."""
    with SubprocVecEnv(WorkerEnvConfig(SHORT, EVENT), num_envs=2, seed=3) as env:
        assert env.num_envs == 2 and env.num_actions == 1
        _check_obs(env.get_observations(), 2)
        keep = torch.full((2, 1), float(KEEP))
        steps, ended = 0, [0, 0]
        while min(ended) == 0:
            obs, rewards, dones, extras = env.step(keep)
            steps += 1
            _check_obs(obs, 2)
            assert rewards.shape == (2,) and rewards.dtype == torch.float32
            assert dones.shape == (2,) and extras["time_outs"].shape == (2,)
            assert torch.equal(extras["time_outs"], dones), "a timeout is the only way these episodes end"
            for i, summary in extras["episodes"]:
                ended[i] += 1
                assert summary["end_reason"] == "timeout" and not summary["success"]
                assert summary["r_T"] == -50.0 and summary["length"] == steps
                assert env.episode_length_buf[i] == 0
                assert "/episode/r_T" in extras["log"]
            assert steps < 3000
        assert env.episodes_done == sum(ended) == len(env.pop_episodes())
    assert all(not p.is_alive() for p in env._procs), "workers must be joined on close"
    env.close()  # idempotent


@pytest.mark.slow
def test_expert_labels_reach_the_goal_as_termination():
    """Driving the workers' own expert labels reaches the goal: done without time_out, r_T = +100."""
    with SubprocVecEnv(WorkerEnvConfig(SHORT, EVENT, expert_labels=True), num_envs=2, seed=0) as env:
        labels = env.expert_actions
        assert labels.shape == (2,) and labels.dtype == torch.long and ((labels >= 0) & (labels < 5)).all()
        summaries = []
        for _ in range(3000):
            _, rewards, dones, extras = env.step(labels.float().unsqueeze(-1))
            labels = extras["expert_actions"]
            for i, summary in extras["episodes"]:
                summaries.append(summary)
                assert dones[i] == 1 and extras["time_outs"][i] == 0
                assert rewards[i] == pytest.approx(100.0)
            if summaries:
                break
        assert summaries and summaries[0]["success"] and summaries[0]["end_reason"] == "goal"


@pytest.mark.slow
def test_dead_worker_is_a_clear_error():
    env = SubprocVecEnv(WorkerEnvConfig(SHORT, EVENT), num_envs=1, seed=0)
    try:
        os.kill(env._procs[0].pid, signal.SIGKILL)
        env._procs[0].join(timeout=10)
        with pytest.raises(WorkerError, match="died"):
            env.step(torch.full((1, 1), float(KEEP)))
    finally:
        env.close()
    assert not env._procs[0].is_alive()


def test_bad_env_options_fail_before_any_worker_starts():
    with pytest.raises(ValueError, match="fidelity"):
        SubprocVecEnv(WorkerEnvConfig(SHORT, {"fidelity": "warp"}), num_envs=1)


def test_training_reward_modes():
    info = {"reward_components": {"r_k": -0.5, "r_T": 100.0}}
    assert training_reward("dense", 99.5, info) == pytest.approx(99.5)
    assert training_reward("sparse", 99.5, info) == pytest.approx(100.0)
    assert training_reward("env", 7.0, info, scale=0.01) == pytest.approx(0.07)
    with pytest.raises(ValueError, match="reward"):
        WorkerEnvConfig(reward="shaped")


def test_replies_that_disagree_on_the_action_mask_are_a_clear_error():
    """A batch mixing a reset (which had an action mask) and a step (which had none) used to die in np.stack
    with a shape message; the flat baseline's 2-worker training did, at its first auto-reset."""
    import numpy as np

    from hbmp_bench.training.vec_env import WorkerVecEnv
    from hbmp_bench.training.worker import StepReply

    env = WorkerVecEnv.__new__(WorkerVecEnv)
    env.device, env.num_envs = "cpu", 2
    obs = {"road": np.zeros(3, np.float32)}
    stacked = env._stack_obs([StepReply(obs), StepReply(obs)])
    assert set(stacked.keys()) == {"road"}
    both = env._stack_obs([StepReply(obs, action_mask=np.ones(5, np.int8))] * 2)
    assert both["action_mask"].shape == (2, 5)
    with pytest.raises(RuntimeError, match="disagree on the action mask"):
        env._stack_obs([StepReply(obs, action_mask=np.ones(5, np.int8)), StepReply(obs)])
