"""The compiled obstacle stage against its numpy reference: the same collisions, ``c_obs`` within
5e-6 relative (the reference sums in float32), the same projection, and the same chosen
trajectory on planning problems recorded from expert episodes in Town01, Town03 and Town05."""

from pathlib import Path as FsPath

import numpy as np
import pytest

from hbmp_bench.planning import Obstacles, Path, PlannerConfig, PlanningProblem, VehicleState, plan, round_corners
from hbmp_bench.planning import obstacle_kernels, planner

DATA = FsPath(__file__).parent / "data" / "recorded_problems.npz"
C_OBS_RTOL, C_OBS_ATOL = 5e-6, 1e-7


def corner_path():
    a = np.linspace(-np.pi / 2, 0.0, 5)
    arc = np.stack([30.0 + 10.0 * np.cos(a), 10.0 + 10.0 * np.sin(a)], axis=1)
    return Path(round_corners(np.vstack([[[-20.0, 0.0]], arc, [[40.0, 60.0]]])))


def random_obstacles(rng, k, centre, spread):
    xy = centre + rng.uniform(-spread, spread, (k, 2))
    return Obstacles(xy[:, 0], xy[:, 1], rng.uniform(-np.pi, np.pi, k), rng.uniform(0.0, 8.0, k),
                     rng.uniform(0.5, 5.0, k), rng.uniform(0.5, 2.2, k))


def recorded_problems():
    d = np.load(DATA)
    path_end = np.cumsum(d["path_n"])
    obs_end = np.cumsum(d["obstacles_n"])
    out = []
    for i in range(len(d["ego"])):
        p0 = path_end[i] - d["path_n"][i]
        o0 = obs_end[i] - d["obstacles_n"][i]
        path = Path._from_arrays(*(d[k][p0:path_end[i]] for k in ("path_xy", "path_s", "path_heading", "path_kappa")))
        v_ref, speed_limit, s_hint = d["scalars"][i]
        out.append(PlanningProblem(VehicleState(*d["ego"][i]), path, float(v_ref), float(speed_limit),
                                   Obstacles.from_rows(d["obstacles"][o0:obs_end[i]]),
                                   s_hint=None if np.isnan(s_hint) else float(s_hint)))
    return out


def test_projection_equals_the_paths_own_including_past_both_ends():
    lp = corner_path().resample(1.0, -5.0, 60.0, extrapolate=True)
    rng = np.random.default_rng(1)
    xy = np.vstack([rng.uniform([-40.0, -20.0], [60.0, 80.0], (300, 2)), [[-60.0, 3.0], [45.0, 90.0]]])
    yaw = rng.uniform(-np.pi, np.pi, len(xy))
    seg = lp.uniform_segments()
    s, e, th = obstacle_kernels.project_poses(xy[:, 0].copy(), xy[:, 1].copy(), yaw, seg.x0, seg.y0, seg.tx, seg.ty,
                                              seg.chord, seg.s, seg.heading, seg.dh)
    s_ref, e_ref, th_ref, _ = lp.project(xy, yaw)
    np.testing.assert_allclose(s, s_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(e, e_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(th, th_ref, rtol=0, atol=1e-9)


def test_kernels_agree_with_the_numpy_reference_on_random_scenes():
    cfg = PlannerConfig()
    path = corner_path()
    lp = path.resample(1.0, -20.0, 80.0, extrapolate=True)
    mixed = 0
    for seed in range(12):
        rng = np.random.default_rng(seed)
        result = plan(PlanningProblem(VehicleState(20.0, 0.5, 0.05, rng.uniform(0.0, 9.0)), path, 8.0, 10.0), cfg)
        X, Y, PSI, _ = (np.ascontiguousarray(a.T[1:]) for a in np.moveaxis(result.trajectories, 2, 0))
        SS, EE = (np.ascontiguousarray(a.T[1:]) for a in np.moveaxis(result.frenet, 2, 0))
        times = result.times[1:]
        obs = random_obstacles(rng, int(rng.integers(1, 5)), np.array([30.0, 2.0]), 12.0)

        first = planner._first_contacts(X, Y, PSI, obs, times, cfg)
        first_ref = planner.first_contacts_reference(X, Y, PSI, obs, times, cfg)
        np.testing.assert_array_equal(first, first_ref)
        hit = first_ref < len(times)
        mixed += 0 < hit.sum() < len(hit) and len(np.unique(first_ref[hit])) > 1  # contacts at different steps

        c = planner._obstacle_cost(SS, EE, obs, lp, times, cfg)
        c_ref = planner.obstacle_cost_reference(SS, EE, obs, lp, times, cfg)
        np.testing.assert_allclose(c, c_ref, rtol=C_OBS_RTOL, atol=C_OBS_ATOL)
    assert mixed >= 3  # scenes where the check tells samples apart


def test_compiled_kernels_equal_their_python_source():
    rng = np.random.default_rng(3)
    T, S, K = 30, 65, 12
    X, Y = rng.uniform(0.0, 30.0, (2, T, S))
    PSI = rng.uniform(-np.pi, np.pi, (T, S))
    o = rng.uniform(0.0, 30.0, (2, K))
    args = (X, Y, PSI, o[0], o[1], rng.uniform(-3, 3, K), rng.uniform(0, 5, K), rng.uniform(1, 5, K),
            rng.uniform(0.5, 2, K), np.arange(1, T + 1) * 0.1, 2.5, 1.15)
    np.testing.assert_array_equal(obstacle_kernels.first_contacts(*args), obstacle_kernels.first_contacts.py_func(*args))
    cost_args = (X, Y, o[0], o[1], rng.uniform(-1, 1, K), rng.uniform(0, 5, K), rng.uniform(1, 5, K),
                 rng.uniform(0.5, 2, K), np.arange(1, T + 1) * 0.1, 4.6, 1.9, 20.0, 10.0, 10.0)
    np.testing.assert_allclose(obstacle_kernels.obstacle_cost(*cost_args),
                               obstacle_kernels.obstacle_cost.py_func(*cost_args), rtol=1e-12, atol=0)


@pytest.mark.parametrize("ignore_followers, decided", [(False, 20), (True, 5)])
def test_same_chosen_trajectory_as_the_reference_on_recorded_problems(monkeypatch, ignore_followers, decided):
    problems = recorded_problems()
    assert len(problems) >= 50
    cfg = PlannerConfig(ignore_followers=ignore_followers)
    compiled = [plan(p, cfg) for p in problems]
    monkeypatch.setattr(planner, "_obstacle_cost", planner.obstacle_cost_reference)
    monkeypatch.setattr(planner, "_first_contacts", planner.first_contacts_reference)
    reference = [planner.plan_reference(p, cfg) for p in problems]
    # the collision check decides some: 34 of the 79 problems with every obstacle checked, 7 without the followers
    assert sum(not r.feasible.all() for r in reference) >= decided
    for a, b in zip(compiled, reference):
        np.testing.assert_array_equal(a.feasible, b.feasible)
        np.testing.assert_array_equal(a.contact_time, b.contact_time)
        np.testing.assert_allclose(a.costs, b.costs, rtol=C_OBS_RTOL, atol=C_OBS_ATOL)
        assert a.chosen == b.chosen
        np.testing.assert_array_equal(a.trajectory, b.trajectory)
