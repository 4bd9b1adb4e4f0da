"""The world's batched per-vehicle work against doing it one vehicle at a time, in SUMO.

``DrivingWorld.step`` runs every vehicle's detectors in one pass (``vehicle.after_sim_steps``) and
builds M_t for every deciding vehicle in one compiled call. Each batched part computes the same
arithmetic per element as its one-by-one form, so the episodes are compared bit for bit: every
observation array, reward, end and info of every agent at every step.
"""

import numpy as np
import pytest

import hbmp_bench.envs.world as world_module
from hbmp_bench.envs import traffic_v0
from hbmp_bench.envs.observation import ObservationBuilder

pytestmark = pytest.mark.slow


def _one_by_one(vehicles, snapshot):
    return [v.after_sim_step(snapshot) for v in vehicles]


def _occupancy_one_by_one(self, requests):
    return [self.occupancy(*r) for r in requests]


def _equal(a, b, where=""):
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for k in a:
            _equal(a[k], b[k], f"{where}/{k}")
    elif isinstance(a, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b)):
            _equal(x, y, f"{where}[{k}]")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape, where
        assert np.array_equal(a, b, equal_nan=True), where
    elif isinstance(a, float) and np.isnan(a):
        assert isinstance(b, float) and np.isnan(b), where
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def _run(fidelity: str, steps: int, agents: int = 1) -> list:
    env = traffic_v0.parallel_env(town="Town01", task="NavigationDynamic", controlled=6 if agents == 1 else "none",
                                  agents=agents, density="dense", fidelity=fidelity, background_fidelity=fidelity)
    rng = np.random.default_rng(7)
    out = []
    try:
        obs, infos = env.reset(seed=3)
        out.append((obs, infos))
        for _ in range(steps):
            if not env.agents:
                break
            actions = {a: int(rng.integers(5)) for a in env.agents if infos[a]["decision_required"]}
            obs, rewards, terms, truncs, infos = env.step(actions)
            out.append((obs, rewards, terms, truncs, infos))
    finally:
        env.close()
    return out


@pytest.mark.parametrize("fidelity, steps, agents", [("event", 120, 1), ("continuous", 25, 1), ("event", 80, 5)])
def test_batched_step_equals_one_vehicle_at_a_time(monkeypatch, fidelity, steps, agents):
    """The ego and 6 circulating agents, or 5 goal-directed agents (``ego`` ... ``ego4``)."""
    batched = _run(fidelity, steps, agents)
    monkeypatch.setattr(world_module, "after_sim_steps", _one_by_one)
    monkeypatch.setattr(ObservationBuilder, "occupancy_all", _occupancy_one_by_one)
    single = _run(fidelity, steps, agents)
    assert len(batched) == len(single) > 1
    for k, (a, b) in enumerate(zip(batched, single)):
        _equal(a, b, f"step {k}")
