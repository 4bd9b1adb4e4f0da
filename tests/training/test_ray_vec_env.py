"""Training workers as Ray actors (a local Ray instance here): the same roll-out as the process
workers for the same seeds, clear errors when an actor dies, and ``hbmp-bench train --backend ray``
end to end."""

import os
import time

import pytest
import torch

from hbmp_bench.cli import main
from hbmp_bench.errors import UnknownNameError
from hbmp_bench.training.run import RunConfig
from hbmp_bench.training.vec_env import RayVecEnv, SubprocVecEnv, WorkerError, make_vec_env
from hbmp_bench.training.worker import WorkerEnvConfig

ray = pytest.importorskip("ray", reason="the ray extra is not installed (pip install 'hbmp-bench[ray]')")

SHORT = "hbmp_bench/Town02-Straight-v0"
CONFIG = WorkerEnvConfig(SHORT, {"fidelity": "event"})
ACTIONS = [0, 0, 4, 1, 0, 4, 0, 0, 0, 2, 0, 3]


def _roll_out(env):
    """Observations, rewards and dones of a fixed action sequence (both envs take the same one)."""
    out = [env.get_observations().clone()]
    for a in ACTIONS:
        obs, rewards, dones, _ = env.step(torch.full((env.num_envs, 1), float(a)))
        out.append((obs.clone(), rewards.clone(), dones.clone()))
    return out


def _kill_and_wait_for_death(actor, timeout_s: float = 60.0) -> None:
    """``ray.kill`` only asks Ray to end the actor: a call sent right after it may still be served. Wait
    until a call fails, so that the step below meets a dead actor, the case under test."""
    ray.kill(actor)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            ray.get(actor.__ray_ready__.remote(), timeout=timeout_s)
        except ray.exceptions.RayActorError:
            return
        time.sleep(0.05)
    pytest.fail(f"the killed Ray actor still answered after {timeout_s:.0f} s")


@pytest.mark.slow
def test_ray_actors_roll_out_what_the_process_workers_do_and_fail_clearly():
    with SubprocVecEnv(CONFIG, num_envs=2, seed=5) as env:
        by_processes = _roll_out(env)
    with RayVecEnv(CONFIG, num_envs=2, seed=5) as env:
        assert ray.is_initialized()
        by_ray = _roll_out(env)
        for a, b in zip(by_processes[1:], by_ray[1:]):
            assert (a[0] == b[0]).all()
            assert torch.equal(a[1], b[1]) and torch.equal(a[2], b[2])
        assert (by_processes[0] == by_ray[0]).all()
        assert by_ray[-1][0]["occupancy"].shape == (2, 1, 64, 36)

        _kill_and_wait_for_death(env._actors[1])
        with pytest.raises(WorkerError, match="worker 1 .*died"):
            env.step(torch.zeros((2, 1)))
    assert not ray.is_initialized()  # the local instance it started is shut down
    env.close()  # idempotent


def test_backend_names_and_address_are_checked():
    with pytest.raises(UnknownNameError, match="process, ray"):
        make_vec_env(CONFIG, 1, backend="mpi")
    with pytest.raises(UnknownNameError, match="process, ray"):
        RunConfig(kind="il", episodes=1, out="x", backend="mpi")
    with pytest.raises(ValueError, match="ray backend only"):
        RunConfig(kind="il", episodes=1, out="x", address="auto")
    with pytest.raises(ValueError, match="ray backend only"):
        make_vec_env(CONFIG, 1, address="auto")


@pytest.mark.slow
def test_train_il_on_ray_writes_a_run(tmp_path):
    out = str(tmp_path / "il")
    assert main(["train", "il", "--scenario", SHORT, "--fidelity", "event", "--episodes", "2", "--workers", "2",
                 "--backend", "ray", "--seed", "0", "--no-progress", "--out", out]) == 0
    for name in ("episodes.csv", "policy.pt", "MODEL_CARD.md"):
        assert os.path.isfile(os.path.join(out, name)), name
    card = open(os.path.join(out, "MODEL_CARD.md")).read()
    assert "--backend ray" in card and "backend: ray" in card
    assert not ray.is_initialized()
