"""Learned agents: shipped checkpoints, ``load_agent("path.pt")``, weights_only loading, clear errors."""

import datetime
import os
from importlib import resources

import pytest
import torch

from hbmp_bench.agents import AGENTS, Agent, load_agent
from hbmp_bench.agents import learned
from hbmp_bench.policies.checkpoints import CheckpointError, save_checkpoint
from hbmp_bench.policies.networks import behavior_model_cfgs, build_model

SHAPES = {"occupancy": [1, 64, 36], "road": [10], "action_mask": [5]}
GROUPS = {"actor": ["occupancy", "road"], "critic": ["occupancy", "road"]}


def _tiny_checkpoint(path, kind="hbmp", mask=False, logits=(0.0, 5.0, 0.0, 0.0, 0.0)):
    actor_cfg, critic_cfg = behavior_model_cfgs(mask_actions=mask)
    actor = build_model(actor_cfg, {k: tuple(v) for k, v in SHAPES.items()}, GROUPS, "actor", 1)
    with torch.no_grad():  # make the policy always answer with these logits (default: speed_down, 1)
        last = [m for m in actor.mlp.modules() if isinstance(m, torch.nn.Linear)][-1]
        last.weight.zero_()
        last.bias.copy_(torch.tensor(logits))
    save_checkpoint(str(path), {
        "kind": kind,
        "model": {"actor": actor_cfg, "critic": critic_cfg, "obs_shapes": SHAPES, "obs_groups": GROUPS,
                  "num_actions": 1, "action_space": "discrete",
                  "env": {"env_id": "hbmp_bench/Training-v0", "observation": "vehicle_centric"}},
        "actor_state_dict": actor.state_dict(),
        "progress": {"episodes": 1, "decisions": 10, "iterations": 1, "wall_s": 1.0},
        "train": {"command": "test", "seed": 0},
    })
    return str(path)


def _obs():
    return {"occupancy": torch.zeros(1, 64, 36).numpy(), "road": torch.zeros(10).numpy()}


def test_learned_agents_are_registered():
    assert {"il", "hbmp", "hbmp-s", "flat"} <= set(AGENTS)


def test_checkpoint_path_loads_with_weights_only_and_acts(tmp_path):
    path = _tiny_checkpoint(tmp_path / "mine.pt")
    torch.load(path, weights_only=True)
    agent = load_agent(path)
    assert isinstance(agent, Agent) and agent.kind == "hbmp" and agent.name == "hbmp"
    assert agent.env_kwargs == {"observation": "vehicle_centric"}
    agent.reset({})
    assert agent.act(_obs(), {"action_mask": [1, 1, 1, 1, 1]}) == 1
    probs = agent.behavior_probabilities(_obs(), {})
    assert probs.shape == (5,) and probs.sum() == pytest.approx(1.0) and probs.argmax() == 1


def test_unmasked_policy_takes_its_best_feasible_behavior(tmp_path):
    """An infeasible choice would run as keep (a standstill trap); the agent takes the best feasible one."""
    agent = load_agent(_tiny_checkpoint(tmp_path / "mine.pt", logits=(0.0, 5.0, 1.0, 3.0, 2.0)))
    assert agent.act(_obs(), {"action_mask": [1, 0, 1, 1, 1]}) == 3
    assert agent.act(_obs(), {"action_mask": [1, 0, 1, 0, 1]}) == 4
    assert agent.act(_obs(), {}) == 1, "no mask given: every behavior is feasible"
    assert agent.act(_obs(), {"action_mask": [0, 0, 0, 0, 0]}) == 1, "an all-zero mask masks nothing"


def test_masked_policy_reads_the_mask_from_info(tmp_path):
    agent = load_agent(_tiny_checkpoint(tmp_path / "masked.pt", mask=True))
    assert agent.act(_obs(), {"action_mask": [1, 0, 1, 1, 1]}) != 1


def test_missing_shipped_checkpoint_names_the_train_command(tmp_path, monkeypatch):
    monkeypatch.setattr(learned.resources, "files", lambda package: tmp_path)
    with pytest.raises(FileNotFoundError, match="hbmp-bench train hbmp-s"):
        load_agent("hbmp-s")


def test_bad_files_are_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="no checkpoint file"):
        load_agent(str(tmp_path / "missing.pt"))
    torch.save({"weights": torch.zeros(2)}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not an hbmp_bench checkpoint"):
        load_agent(str(tmp_path / "other.pt"))
    with pytest.raises(ValueError, match="weights_only"):
        save_checkpoint(str(tmp_path / "x.pt"), {"kind": "il", "model": {"obs": object()}})
    assert not os.path.exists(tmp_path / "x.pt")


def test_refused_and_damaged_files_are_checkpoint_errors(tmp_path):
    """torch's own errors (whose text offers to load unsafely) stay the cause, out of the message."""
    torch.save({"when": datetime.datetime(2026, 1, 1)}, tmp_path / "pickled.pt")
    with pytest.raises(CheckpointError, match=r"is refused: it stores a Python object \(datetime.datetime\)") as err:
        load_agent(str(tmp_path / "pickled.pt"))
    assert "weights_only=False" not in str(err.value) and err.value.__cause__ is not None
    good = _tiny_checkpoint(tmp_path / "good.pt")
    data = open(good, "rb").read()
    for name, content in (("cut.pt", data[: len(data) // 3]), ("text.pt", b"hello"), ("empty.pt", b"")):
        (tmp_path / name).write_bytes(content)
        with pytest.raises(CheckpointError, match="the file is truncated, damaged or not a torch checkpoint"):
            load_agent(str(tmp_path / name))


SHIPPED = [name for name in learned.TRAIN_COMMANDS
           if os.path.isfile(str(resources.files("hbmp_bench.agents") / "checkpoints" / f"{name}.pt"))]


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_checkpoints_have_a_model_card_and_act_in_a_real_env(name):
    folder = resources.files("hbmp_bench.agents") / "checkpoints"
    card = (folder / f"{name}.md").read_text()
    kind = learned.trained_kind(name)  # flat-ilrl: the flat kind from flat-il
    for needle in (f"hbmp-bench train {kind}", "seed:", "episodes:", "wall time:", "machine:"):
        assert needle in card
    ckpt = torch.load(str(folder / f"{name}.pt"), weights_only=True)
    assert ckpt["kind"] == kind and "optimizer_state_dict" not in ckpt
    if kind != name:  # the card's command is the one the checkpoint records (e.g. its --init)
        assert ckpt["train"]["command"] in card
    agent = load_agent(name)
    if not agent.discrete:
        return
    from hbmp_bench.envs import make

    env = make("hbmp_bench/Town01-Straight-v0", fidelity="event", **agent.env_kwargs)
    try:
        obs, info = env.reset(seed=0)
        agent.reset(info)
        actions = []
        for _ in range(20):
            actions.append(agent.act(obs, info))
            obs, _, terminated, truncated, info = env.step(actions[-1])
            if terminated or truncated:
                break
        assert all(isinstance(a, int) and 0 <= a < 5 for a in actions)
    finally:
        env.close()


def test_il_is_shipped():
    assert "il" in SHIPPED, "the il checkpoint ships with the package"
