"""flat-il, DAgger on the expert's controls: the label is the control the expert's behavior driver applies in
the ego's state, and a short real run gives a checkpoint the agent loads and drives the control env with."""

import numpy as np
import pytest
import torch

from hbmp_bench.agents import load_agent
from hbmp_bench.agents.expert import ExpertAgent
from hbmp_bench.cli import main
from hbmp_bench.envs.control_env import ControlEnv
from hbmp_bench.envs.drivers import feasible_behaviors
from hbmp_bench.envs.world import EGO_ID
from hbmp_bench.errors import UserError
from hbmp_bench.planning import Control
from hbmp_bench.planning import step as bicycle_step
from hbmp_bench.policies.checkpoints import load_checkpoint
from hbmp_bench.policies.networks import COMPACT_NETWORK
from hbmp_bench.sim.sumo import EGO_TYPE
from hbmp_bench.training.commands import CONTROL_ENV, resolve_init
from hbmp_bench.training.control_dagger import DaggerControlConfig, train_control_dagger
from hbmp_bench.training.expert_control import ExpertControl
from hbmp_bench.training.dagger import DemoDataset
from hbmp_bench.training.run import RunConfig
from hbmp_bench.training.runlog import read_csv
from hbmp_bench.training.worker import WorkerEnvConfig, make_env


def _model_tuple(m):
    return np.array([m.x, m.y, m.yaw, m.v, m.steer])


@pytest.mark.slow
def test_label_is_the_control_the_expert_behavior_driver_applies():
    """In states the expert's stack did not drive to (a swerve to the left), the label is the first control
    period of the expert's behavior on the continuous fidelity's driver: driving the control env with the label
    puts the ego where that driver, begun with the expert's behavior in the same state, would have put it."""
    env = ControlEnv(town="Town02", task="Straight", privileged=True)
    labeler = ExpertControl(ExpertAgent())
    expert = ExpertAgent()
    try:
        obs, info = env.reset(seed=3)
        labeler.reset(info)
        expert.reset(info)
        labels = []
        for t in range(40):
            world = env.world
            ego = world.ego
            behavior, label = labeler.label(env, obs, info)
            mask = feasible_behaviors(world.net, ego.state.lane, ego.state.lane_pos)
            assert behavior == expert.act(obs, {**info, "action_mask": mask})
            assert label.shape == (2,) and label.dtype == np.float32 and np.all(np.abs(label) <= 1.0)
            reference = world.make_driver(EGO_ID, EGO_TYPE, "continuous")
            reference.model = before = ego.driver.model
            reference.begin(behavior if mask[behavior] else 4, ego.state, ego.route.begin_lane(), ego.next_edges(),
                            ego.next_lanes())
            assert reference.before_step(ego.actors)
            expected = reference.model
            control = Control(steer=float(label[1]), throttle=max(float(label[0]), 0.0),
                              brake=max(-float(label[0]), 0.0))
            assert _model_tuple(bicycle_step(before, control, 0.1, world.config.continuous.vehicle)) == \
                pytest.approx(_model_tuple(expected), abs=1e-6)
            labels.append(label)
            swerve = 15 <= t < 25  # off the expert's path for a while: the label is asked in the learner's states
            obs, _, terminated, truncated, info = env.step(np.array([0.2, 0.4], dtype=np.float32) if swerve else label)
            if not swerve:
                assert _model_tuple(env.world.ego.driver.model) == pytest.approx(_model_tuple(expected), abs=1e-6)
            assert not (terminated or truncated)
        labels = np.array(labels)
        assert labels[:5, 0].min() > 0.0, "from standstill the expert speeds up: throttle"
        assert labels[25:28, 1].min() < 0.0, "after the swerve to the left the expert steers back right"
    finally:
        env.close()


@pytest.mark.slow
def test_short_run_gives_a_checkpoint_the_agent_drives_the_control_env_with(tmp_path):
    """Three real episodes (one worker, CPU): a flat-il checkpoint with the flat baseline's Gaussian output,
    trained on every visited state's expert control; the agent loads it and drives the control env, and PPO on
    the flat baseline starts from it (``train flat --init``)."""
    out = str(tmp_path / "flat-il")
    env_config = WorkerEnvConfig("hbmp_bench/Town02-Straight-v0", entry_point=CONTROL_ENV, reward="env")
    config = DaggerControlConfig(decisions_per_round=128, updates_per_round=20, batch_size=32, holdout_fraction=0.3)
    result = train_control_dagger(RunConfig("flat-il", episodes=3, out=out, workers=1, seed=2, progress=False),
                                  env_config, config)
    ckpt = load_checkpoint(result["policy"], kinds=("flat-il",))
    assert "optimizer_state_dict" not in ckpt and ckpt["progress"]["episodes"] == 3
    model = ckpt["model"]
    assert model["action_space"] == "box" and model["num_actions"] == 2
    assert model["actor"]["distribution_cfg"]["class_name"] == "rsl_rl.modules.distribution:GaussianDistribution"
    train = DemoDataset({"occupancy": (1, 64, 36), "road": (12,)}, (2,))
    with np.load(f"{out}/dataset.npz") as arrays:
        train.load_state_dict(arrays, "train")
    _, labels = train.get(np.arange(len(train)))
    assert len(train) > 100 and labels.shape == (len(train), 2) and labels.dtype == torch.float32
    assert labels[:, 0].max() > 0.0 and labels[:, 0].min() < 0.0, "throttle and brake were demonstrated"
    rounds = read_csv(f"{out}/rounds.csv")
    assert np.isfinite(rounds["loss"]).any() and rounds["dataset"][-1] == len(train)
    assert read_csv(f"{out}/episodes.csv")["episode"].tolist() == [1, 2, 3]

    agent = load_agent(result["policy"])
    assert agent.kind == "flat-il" and not agent.discrete and agent.env_factory == CONTROL_ENV
    env = make_env(WorkerEnvConfig("hbmp_bench/Town02-Straight-v0", env_config.env_kwargs, entry_point=CONTROL_ENV))
    try:
        obs, info = env.reset(seed=0)
        agent.reset(info)
        action = agent.act(obs, info)
        assert action.shape == (2,) and action.dtype == np.float32 and np.all(np.abs(action) <= 1.0)
        _, _, terminated, truncated, info = env.step(action)
        assert info["control"] == pytest.approx(action.tolist())
    finally:
        env.close()

    # flat-ilrl: PPO on the flat baseline from this actor, with its (compact) layer sizes and its weights
    ppo_out = str(tmp_path / "flat-ilrl")
    assert main(["train", "flat", "--init", result["policy"], "--episodes", "1", "--workers", "1", "--out", ppo_out,
                 "--scenario", "hbmp_bench/Town02-Straight-v0", "--seed", "0", "--critic-warmup", "1",
                 "--no-progress"]) == 0
    ppo = load_checkpoint(f"{ppo_out}/policy.pt", kinds=("flat",))
    assert ppo["train"]["init"] == result["policy"]
    assert {k: ppo["model"]["actor"][k] for k in COMPACT_NETWORK} == COMPACT_NETWORK
    frozen = ppo["actor_state_dict"]  # the actor learnt nothing during the critic's warm-up
    assert all(torch.equal(frozen[k], v) for k, v in ckpt["actor_state_dict"].items())


def test_flat_il_takes_no_init_and_flat_starts_from_a_control_policy():
    with pytest.raises(UserError, match="--init does not apply to flat-il"):
        resolve_init("flat-il", "il")
    assert resolve_init("flat-il", None) is None and resolve_init("flat", None) is None
    with pytest.raises(UserError, match="the flat baseline starts from a control policy"):
        resolve_init("flat", "il")
