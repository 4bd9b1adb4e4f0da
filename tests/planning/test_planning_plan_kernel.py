"""The single planning kernel against the numpy form it was written from (``plan_reference``): equal
arrays, bit for bit (tolerance 0), and the same chosen trajectory, on planning problems recorded from
expert episodes in Town01, Town03 and Town05 and on random ones (no hint, several configs)."""

import numpy as np
import pytest
from test_planning_obstacle_kernels import corner_path, random_obstacles, recorded_problems

from hbmp_bench.planning import Path, PlannerConfig, PlanningProblem, VehicleState, plan, planner
from hbmp_bench.planning.plan_kernel import pairwise_sum

ARRAYS = ("times", "trajectories", "omega", "frenet", "costs", "total", "feasible", "contact_time")
CONFIGS = {
    "default": PlannerConfig(),
    "paper gains, no limits": PlannerConfig(gain_speed=np.inf, lat_accel_max=np.inf, curve_lat_accel=np.inf),
    "one sample, brake fallback": PlannerConfig(n_v=1, n_omega=1, horizon=2.0, infeasible_fallback="brake"),
    "fine path, long horizon": PlannerConfig(path_resolution=0.5, horizon=5.0, n_v=5, n_omega=11),
    "followers checked": PlannerConfig(ignore_followers=False),
    "followers checked, min_cost fallback": PlannerConfig(ignore_followers=False, infeasible_fallback="min_cost"),
}


def assert_same(a, b):
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert (a.chosen, a.collision_free, a.brake_index, a.v_ref) == (b.chosen, b.collision_free, b.brake_index, b.v_ref)


@pytest.mark.parametrize("config", list(CONFIGS))
def test_equal_to_the_reference_on_recorded_problems(config):
    cfg = CONFIGS[config]
    problems = recorded_problems()
    chosen = set()
    for p in problems:
        result = plan(p, cfg)
        assert_same(result, planner.plan_reference(p, cfg))
        chosen.add(result.chosen)
    assert len(chosen) >= (1 if cfg.n_samples == 3 else 3)  # the problems tell samples apart


def test_equal_to_the_reference_without_a_hint_on_random_problems():
    path = corner_path()
    limited = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        ego = VehicleState(*rng.uniform([-25.0, -3.0, -0.6, 0.0], [45.0, 62.0, 2.2, 14.0]))
        obstacles = random_obstacles(rng, int(rng.integers(0, 8)), np.array([ego.x, ego.y]) + 10.0, 25.0)
        problem = PlanningProblem(ego, path, float(rng.uniform(0.0, 14.0)), 12.0, obstacles)
        for cfg in CONFIGS.values():
            result = plan(problem, cfg)
            assert_same(result, planner.plan_reference(problem, cfg))
            limited += result.v_ref < problem.v_ref  # the curve speed cap took part
    assert limited >= 3  # problems where the curve speed cap took part


def test_pairwise_sum_is_numpys():
    rng = np.random.default_rng(0)
    for n in [*range(0, 300), 1000, 4099]:
        a = rng.uniform(-5.0, 5.0, n) * 10.0 ** rng.uniform(-3.0, 3.0, n)
        assert pairwise_sum(a, 0, n) == np.add.reduce(a)
    a = rng.uniform(0.0, 1.0, 500)
    assert pairwise_sum(a, 7, 300) == np.add.reduce(a[7:307])


def test_project_pose_is_the_paths_projection():
    """The compiled single-pose projection gives Path.project's four floats, with and without a hint, on
    and off the path, past both ends."""
    path = corner_path()
    rng = np.random.default_rng(5)
    for _ in range(500):
        x, y, yaw = rng.uniform([-40.0, -20.0, -np.pi], [60.0, 80.0, np.pi])
        hint = None if rng.random() < 0.3 else float(rng.uniform(-20.0, path.length + 20.0))
        assert path.project_pose(x, y, yaw, hint) == path.project(np.array([x, y]), yaw, hint_s=hint)


def test_project_poses_is_the_paths_projection():
    """The compiled projection of many poses without a hint gives Path.project's arrays, on a rounded
    corner and on coarse polylines (points past both ends, behind and beside)."""
    rng = np.random.default_rng(6)
    coarse = Path(rng.uniform(0.0, 40.0, (12, 2)).cumsum(axis=0), max_spacing=None)
    for path in (corner_path(), coarse, Path([[0.0, 0.0], [50.0, 0.0]], max_spacing=None)):
        for _ in range(40):
            m = int(rng.integers(1, 40))
            xy, yaw = rng.uniform(-100.0, 500.0, (m, 2)), rng.uniform(-4.0, 4.0, m)
            for got, expect in zip(path.project_poses(xy, yaw), path.project(xy, yaw)):
                np.testing.assert_array_equal(got, expect)
