"""Many learners per simulation: the goal-directed vehicles of one scene as slots of the training VecEnv
(``WorkerEnvConfig.agents``, :class:`~hbmp_bench.training.worker.SceneRunner`), each respawned at a new start
when its episode ends; continuous scenes: ``test_async_rollout``)."""

import numpy as np
import pytest
import torch

from hbmp_bench.errors import ConfigError
from hbmp_bench.training.vec_env import make_vec_env
from hbmp_bench.training.worker import SceneRunner, WorkerEnvConfig, asynchronous_scene

pytestmark = pytest.mark.slow


def test_every_learner_is_a_slot_and_a_finished_one_comes_back():
    config = WorkerEnvConfig(env_kwargs={"fidelity": "event", "density": "regular"}, agents=3)
    env = make_vec_env(config, 1, seed=0)
    try:
        assert env.num_envs == 3 and env.num_workers == 1
        assert env.get_observations()["occupancy"].shape[0] == 3
        episodes, arrivals, generator = [], 0, torch.Generator().manual_seed(0)
        done_before = torch.zeros(3, dtype=torch.long)
        for step in range(400):
            actions = torch.randint(0, 5, (3, 1), generator=generator).float()
            if step % 4:
                actions[:] = 0.0  # mostly speed_up: episodes end within the run
            obs, rewards, dones, extras = env.step(actions)
            assert torch.isfinite(rewards).all() and torch.isfinite(obs["road"]).all()
            episodes += [e for _, e in extras["episodes"]]
            # the step after an end is the slot's arrival: it ends there too, with no episode and no reward
            arrived = done_before.bool() & dones.bool()
            arrivals += int(arrived.sum())
            assert all(i not in {k for k, _ in extras["episodes"]} or not arrived[i] for i in range(3))
            done_before = dones
        assert len(episodes) >= 3 and arrivals >= 3
        assert all(e["end_reason"] in ("goal", "violation", "collision", "timeout", "left_network") for e in episodes)
        assert env.episodes_done == len(episodes)
    finally:
        env.close()


def test_a_scene_is_asynchronous_only_with_continuous_behaviors():
    continuous = WorkerEnvConfig(env_kwargs={"fidelity": "continuous"}, agents=2)
    assert asynchronous_scene(continuous)
    assert not asynchronous_scene(WorkerEnvConfig(env_kwargs={"fidelity": "event"}, agents=2))
    assert not asynchronous_scene(WorkerEnvConfig(env_kwargs={"fidelity": "continuous"}, agents=1))
    assert not asynchronous_scene(WorkerEnvConfig(entry_point="hbmp_bench.envs.control_env:ControlEnv", agents=2))
    with pytest.raises(ConfigError, match="agents"):
        WorkerEnvConfig(agents=0)
    env = make_vec_env(continuous, 1, seed=0)
    try:
        with pytest.raises(RuntimeError, match="step_slots"):
            env.step(torch.zeros(2, 1))
    finally:
        env.close()


def test_a_scene_of_learners_seeds_like_one():
    config = WorkerEnvConfig(env_kwargs={"fidelity": "event", "density": "regular"}, agents=2)
    runs = []
    for _ in range(2):
        runner = SceneRunner(config)
        try:
            replies = runner.reset(7)
            for _ in range(30):
                replies = runner.step([0, 4])
            runs.append([np.asarray(r.obs["road"]) for r in replies])
        finally:
            runner.close()
    assert all(np.array_equal(a, b) for a, b in zip(*runs))
