"""docs/recipes.md runs: each training script there, executed as written except for the step counts
at its top (made small), with what it trained checked."""

import re
from pathlib import Path

import numpy as np
import pytest

RECIPES = Path(__file__).resolve().parents[2] / "docs" / "recipes.md"

pytestmark = pytest.mark.slow


def recipe(library: str) -> str:
    """The python block of ``docs/recipes.md`` whose docstring names ``library``."""
    blocks = re.findall(r"```python\n(.*?)```", RECIPES.read_text(encoding="utf-8"), flags=re.S)
    found = [b for b in blocks if library in b.splitlines()[0]]
    assert len(found) == 1, f"one {library} recipe expected, found {len(found)}"
    return found[0]


def run(library: str, tmp_path, monkeypatch, **small) -> dict:
    """Execute the recipe with each ``NAME = ...`` line of ``small`` replaced; returns its globals."""
    source = recipe(library)
    for name, value in small.items():
        source, n = re.subn(rf"^{name} = .*$", f"{name} = {value!r}", source, count=1, flags=re.M)
        assert n == 1, f"{name} is not a setting of the {library} recipe"
    monkeypatch.chdir(tmp_path)
    scope = {"__name__": "__main__"}
    exec(compile(source, f"{RECIPES}:{library}", "exec"), scope)
    return scope


def test_the_sb3_recipe(tmp_path, monkeypatch):
    pytest.importorskip("stable_baselines3")
    scope = run("Stable-Baselines3) on the HBMP", tmp_path, monkeypatch, TOTAL_STEPS=256, N_ENVS=2, N_STEPS=64,
                MAX_CYCLES=40)
    model = scope["model"]
    assert model.num_timesteps >= 256 and (tmp_path / "ppo_hbmp.zip").is_file()
    assert len(model.ep_info_buffer) >= 4 and all(e["l"] <= 40 for e in model.ep_info_buffer)


def test_the_supersuit_recipe(tmp_path, monkeypatch):
    pytest.importorskip("supersuit")
    scope = run("through SuperSuit", tmp_path, monkeypatch, TOTAL_STEPS=384, N_COPIES=2, CONTROLLED=2, N_STEPS=32,
                MAX_CYCLES=24)
    model = scope["model"]
    assert scope["vec_env"].num_envs == 6, "2 copies x (the ego + 2 agents), one shared policy"
    assert model.num_timesteps >= 384 and (tmp_path / "ppo_hbmp_shared.zip").is_file()
    assert len(model.ep_info_buffer) >= 12 and all(e["l"] == 24 for e in model.ep_info_buffer)


def test_the_rllib_recipe(tmp_path, monkeypatch):
    pytest.importorskip("ray.rllib")
    import ray

    scope = run("(RLlib)", tmp_path, monkeypatch, ITERATIONS=1, ENV_RUNNERS=0, TRAIN_BATCH=64, MINIBATCH=32,
                ENV_CONFIG=dict(town="Town01", task="NavigationDynamic", episode_index=0, controlled=2, max_cycles=30))
    assert not ray.is_initialized()
    result = scope["result"]
    runners = result["env_runners"]
    assert runners["num_env_steps_sampled"] >= 64 and runners["num_episodes"] >= 1
    sampled = runners["num_agent_steps_sampled"]
    assert set(sampled) == {"ego", "bg0", "bg1"}
    assert sampled["ego"] < sampled["bg0"], "the continuous ego is observed only when it decides"
    assert "shared" in result["learners"] and np.isfinite(result["learners"]["shared"]["total_loss"])
    assert (tmp_path / "ppo_hbmp_rllib").is_dir()
