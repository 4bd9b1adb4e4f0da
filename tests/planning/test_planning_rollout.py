"""The compiled roll-out: same numbers as its interpreted source, Frenet coordinates that agree
with the general projector on curved, kinked references."""

import numpy as np
import pytest

from hbmp_bench.planning import Path, PlannerConfig, PlanningProblem, VehicleState, plan, round_corners
from hbmp_bench.planning import rollout


def corner_path():
    """A 90-degree left corner from SUMO-like coarse vertices (4 m chords), rounded."""
    a = np.linspace(-np.pi / 2, 0.0, 5)
    arc = np.stack([30.0 + 10.0 * np.cos(a), 10.0 + 10.0 * np.sin(a)], axis=1)
    xy = np.vstack([[[-20.0, 0.0]], arc, [[40.0, 60.0]]])
    return Path(round_corners(xy))


def roll_out_inputs(path, ego, cfg=PlannerConfig()):
    """Inputs of one roll-out as plan() builds them, with a spread of speeds and offsets."""
    T, S = cfg.n_steps + 1, 12
    s0, e0, th0, k0 = path.project(ego.xy, ego.yaw)
    rng = np.random.default_rng(0)
    V = np.repeat(rng.uniform(0.5, 9.0, S)[None, :], T, axis=0)
    lp = path.resample(cfg.path_resolution, s0 - 12.0, s0 + 9.0 * cfg.horizon + 20.0, extrapolate=True)
    return (ego.x, ego.y, ego.yaw, s0, e0, th0, k0, V, np.full((T, S), cfg.k_theta),
            np.full((T, S), cfg.k_e), np.full((T, S), 0.6), rng.uniform(-0.3, 0.3, S), 5, cfg.dt, 2, 2,
            *lp.uniform_segments())


def test_compiled_roll_out_equals_its_python_source(monkeypatch):
    args = roll_out_inputs(corner_path(), VehicleState(20.0, 0.8, 0.1, 6.0))
    compiled = rollout.roll_out(*args)
    monkeypatch.setattr(rollout, "_project", rollout._project.py_func)
    interpreted = rollout.roll_out.py_func(*args)
    for a, b in zip(compiled, interpreted):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def test_roll_out_frenet_agrees_with_the_general_projector_on_a_corner():
    path = corner_path()
    r = plan(PlanningProblem(VehicleState(20.0, 0.8, 0.1, 6.0), path, 6.0, 10.0))
    xy = r.trajectories[:, :, :2].reshape(-1, 2)
    hint = r.frenet[:, :, 0].ravel()
    s, e = path.frenet(xy, hint_s=hint, window=(3.0, 3.0))
    inside = (s > path.s[0] + 1.0) & (s < path.s[-1] - 1.0)
    assert inside.mean() > 0.9
    # the roll-out projects on a copy resampled at 1 m: its chords cut the R = 10 m corner by
    # at most 1 / (8 R) = 1.25 cm, so it may differ by that much, never by a lost segment
    np.testing.assert_allclose(r.frenet[:, :, 0].ravel()[inside], s[inside], atol=0.05)
    np.testing.assert_allclose(r.frenet[:, :, 1].ravel()[inside], e[inside], atol=0.05)


def test_uniform_segments_rejects_a_non_uniform_path():
    with pytest.raises(ValueError, match="uniform"):
        Path([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]], max_spacing=None).uniform_segments()
