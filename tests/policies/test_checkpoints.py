"""Checkpoint files: the shipped ones still load (written when the networks lived in ``training``), and an
agent process builds a learned policy without importing any training code."""

import subprocess
import sys
from importlib import resources

import pytest
import torch

from hbmp_bench.agents.learned import TRAIN_COMMANDS, shipped_checkpoint
from hbmp_bench.policies.checkpoints import (
    FORMER_NETWORK_CLASSES,
    NETWORK_CLASSES,
    CheckpointError,
    build_actor,
    check_network_classes,
    current_class_names,
    load_checkpoint,
)


def _class_names(value):
    if isinstance(value, dict):
        for k, v in value.items():
            yield from [v] if k == "class_name" else _class_names(v)
    elif isinstance(value, list):
        for v in value:
            yield from _class_names(v)


@pytest.mark.parametrize("name", sorted(TRAIN_COMMANDS))
def test_shipped_checkpoints_load_and_name_the_current_classes(name):
    raw = torch.load(shipped_checkpoint(name), map_location="cpu", weights_only=True)
    loaded = load_checkpoint(shipped_checkpoint(name))
    assert set(_class_names(loaded["model"])) <= set(NETWORK_CLASSES)
    assert list(_class_names(loaded["model"])) == [FORMER_NETWORK_CLASSES.get(c, c) for c in _class_names(raw["model"])]
    actor = build_actor(raw)  # a dict that did not come from load_checkpoint, naming the former classes
    assert type(actor).__module__ == "hbmp_bench.policies.networks"


def test_former_names_are_the_only_other_ones_accepted():
    model = {"actor": {"class_name": "hbmp_bench.training.models:BehaviorNetwork",
                       "distribution_cfg": {"class_name": "os:system"}}}
    with pytest.raises(CheckpointError, match="os:system"):
        check_network_classes({"model": model})
    assert current_class_names(model)["actor"]["class_name"] == "hbmp_bench.policies.networks:BehaviorNetwork"


def test_an_agent_builds_its_policy_without_training_code():
    code = ("import sys; from hbmp_bench.agents import load_agent; load_agent('il'); "
            "print(sorted(m for m in sys.modules if m.startswith('hbmp_bench.training')))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert done.stdout.strip() == "[]"
    assert (resources.files("hbmp_bench.agents") / "checkpoints" / "il.pt").is_file()
