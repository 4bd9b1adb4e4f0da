"""DAgger: the β schedule, the bit-packed dataset, and a short real run where agreement with the
expert rises on held-out episodes; resuming continues the same run."""

import shutil

import numpy as np
import pytest
import torch

from hbmp_bench.errors import UserError
from hbmp_bench.policies.checkpoints import build_actor, load_checkpoint
from hbmp_bench.training.dagger import DaggerConfig, DemoDataset, agreement, expert_probability, train_dagger
from hbmp_bench.policies.networks import behavior_model_cfgs, build_model
from hbmp_bench.training.run import RunConfig
from hbmp_bench.training.runlog import read_csv
from hbmp_bench.training.worker import WorkerEnvConfig


def test_beta_holds_then_decays_linearly_to_zero_over_the_budget():
    budget = 1000
    assert expert_probability(0, budget) == 0.95
    assert expert_probability(299, budget) == 0.95  # hold: first 30 % of the budget
    assert expert_probability(300, budget) == pytest.approx(0.95)
    assert expert_probability(650, budget) == pytest.approx(0.95 * 0.5)
    assert expert_probability(999, budget) == pytest.approx(0.95 / 700)
    assert expert_probability(1000, budget) == 0.0
    betas = [expert_probability(e, budget) for e in range(budget)]
    assert all(a >= b for a, b in zip(betas, betas[1:])), "never increases"
    # the paper's schedule: 0.95 for 3000 episodes, then a decay (scaled: hold_fraction)
    assert expert_probability(2999, 6000, hold_fraction=0.5) == 0.95
    assert expert_probability(4500, 6000, hold_fraction=0.5) == pytest.approx(0.475)
    with pytest.raises(ValueError):
        expert_probability(0, 0)


def test_dataset_packs_the_grid_and_round_trips(tmp_path):
    rng = np.random.default_rng(0)
    data = DemoDataset({"occupancy": (1, 64, 36), "road": (10,)})
    batches = []
    for n in (700, 900):  # crosses the initial capacity
        occ = (rng.random((n, 1, 64, 36)) < 0.2).astype(np.float32)
        road = rng.random((n, 10)).astype(np.float32)
        labels = rng.integers(0, 5, n).astype(np.int8)
        data.add({"occupancy": occ, "road": road}, labels)
        batches.append((occ, road, labels))
    assert len(data) == 1600
    assert data._data["occupancy"].shape[1] == 288, "64·36 cells bit-packed into 288 bytes"
    obs, labels = data.get(np.array([0, 699, 700, 1599]))
    assert torch.equal(obs["occupancy"][1], torch.from_numpy(batches[0][0][699]))
    assert torch.equal(obs["occupancy"][2], torch.from_numpy(batches[1][0][0]))
    assert torch.equal(obs["road"][3], torch.from_numpy(batches[1][1][-1]))
    assert labels.tolist() == [batches[0][2][0], batches[0][2][699], batches[1][2][0], batches[1][2][-1]]
    np.savez(tmp_path / "d.npz", **data.state_dict("train"))
    again = DemoDataset(data.shapes)
    with np.load(tmp_path / "d.npz") as arrays:
        again.load_state_dict(arrays, "train")
    assert len(again) == 1600 and torch.equal(again.get(np.arange(1600))[0]["occupancy"], data.get(np.arange(1600))[0]["occupancy"])
    with pytest.raises(ValueError, match="binary"):
        data.add({"occupancy": np.full((1, 1, 64, 36), 0.5, np.float32), "road": np.zeros((1, 10), np.float32)},
                 np.zeros(1, np.int8))


@pytest.mark.slow
def test_dagger_learns_the_expert_on_held_out_episodes_and_resumes(tmp_path):
    """About a thousand decisions on short Town02 routes, a training round every 128: afterwards the
    policy agrees with the expert on held-out episodes far more often than the same network before
    training, and more often than always answering the most common label: it removes most of the
    disagreement of either (measured as disagreement, since how often the most common label
    occurs depends on the expert's rules)."""
    out = str(tmp_path / "il")
    env = WorkerEnvConfig("hbmp_bench/Town02-Straight-v0", {"fidelity": "event"})
    cfg = DaggerConfig(decisions_per_round=128, updates_per_round=30, batch_size=64, holdout_fraction=0.4)
    result = train_dagger(RunConfig("il", episodes=10, out=out, workers=2, seed=1, progress=False), env, cfg)
    ckpt = load_checkpoint(result["policy"], kinds=("il",))
    assert "optimizer_state_dict" not in ckpt and ckpt["progress"]["episodes"] == 10

    holdout = DemoDataset({"occupancy": (1, 64, 36), "road": (10,)})
    train = DemoDataset(holdout.shapes)
    with np.load(f"{out}/dataset.npz") as arrays:
        holdout.load_state_dict(arrays, "holdout")
        train.load_state_dict(arrays, "train")
    assert len(holdout) > 50 and len(train) > len(holdout)
    torch.manual_seed(1)
    untrained = build_model(behavior_model_cfgs()[0], holdout.shapes, ckpt["model"]["obs_groups"], "actor", 1)
    trained = build_actor(ckpt)
    before, after = agreement(untrained, holdout), agreement(trained, holdout)
    majority = holdout.label_counts().max() / len(holdout)
    assert 1.0 - after < 0.4 * min(1.0 - before, 1.0 - majority), (before, after, majority)
    rounds = read_csv(f"{out}/rounds.csv")
    assert rounds["loss"][-1] < rounds["loss"][0] / 2

    eps = read_csv(f"{out}/episodes.csv")
    assert eps["episode"].tolist() == list(range(1, 11)) and eps["beta"][0] == pytest.approx(0.95)
    assert eps["beta"][-1] < 0.5, "β decays over the budget"
    copy = tmp_path / "without_dataset"
    copy.mkdir()
    shutil.copy(f"{out}/checkpoint.pt", copy)
    with pytest.raises(UserError, match="dataset.npz is missing beside the checkpoint"):
        train_dagger(RunConfig("il", episodes=11, out=str(copy), workers=1, seed=1, progress=False,
                               resume=str(copy / "checkpoint.pt")), env, cfg)
    assert sorted(p.name for p in copy.iterdir()) == ["checkpoint.pt"], "refused before anything was written"
    resumed = train_dagger(RunConfig("il", episodes=11, out=out, workers=1, seed=1, progress=False,
                                     resume=f"{out}/checkpoint.pt"), env, cfg)
    assert resumed["progress"]["episodes"] == 11
    assert read_csv(f"{out}/episodes.csv")["episode"].tolist() == list(range(1, 12))
    assert read_csv(f"{out}/rounds.csv")["dataset"][-1] > len(train), "the aggregated dataset was carried over"
