"""The tracker's compiled look-ups give numpy's floats: ``np.interp`` of the planned speed and the
pure-pursuit look-ahead point (:func:`lookahead_point_reference`), on planned trajectories and on
degenerate paths (standing, repeated points, looking past the end)."""

import numpy as np

from hbmp_bench.planning import Path, PlannerConfig, PlanningProblem, VehicleState, plan
from hbmp_bench.planning.tracking import lookahead_point_reference
from hbmp_bench.planning.tracking_kernel import interp, lookahead_point


def planned_trajectories():
    xs = np.linspace(0.0, 120.0, 61)
    path = Path(np.stack([xs, 0.002 * (xs - 40.0) ** 2], axis=1))
    rng = np.random.default_rng(4)
    for _ in range(20):
        ego = VehicleState(float(rng.uniform(0.0, 60.0)), float(rng.uniform(-2.0, 5.0)), float(rng.uniform(-0.4, 0.4)),
                           float(rng.uniform(0.0, 12.0)))
        result = plan(PlanningProblem(ego, path, float(rng.uniform(0.0, 12.0)), 12.0), PlannerConfig())
        yield from result.trajectories[::7]


def test_interp_is_numpys():
    rng = np.random.default_rng(0)
    times = np.arange(31) * 0.1
    for traj in planned_trajectories():
        v = traj[:, 3]
        for x in [*rng.uniform(-0.5, 3.5, 20), *times, -0.0, 3.0, np.nan]:
            got, expect = interp(float(x), times, v), float(np.interp(x, times, v))
            assert got == expect or (np.isnan(got) and np.isnan(expect))


def test_lookahead_point_is_the_numpy_form():
    rng = np.random.default_rng(1)
    cases = list(planned_trajectories())
    standing = np.zeros((31, 4))
    stutter = np.repeat(np.stack([np.linspace(0.0, 10.0, 8), np.zeros(8)], axis=1), 3, axis=0)
    for traj in [*cases, standing, np.hstack([stutter, np.zeros((len(stutter), 2))])]:
        for _ in range(10):
            p = traj[rng.integers(len(traj)), :2] + rng.normal(0.0, 2.0, 2)
            dist = float(rng.uniform(0.5, 60.0))
            expect = lookahead_point_reference(traj[:, :2], p, dist)
            assert lookahead_point(traj, float(p[0]), float(p[1]), dist) == (expect[0], expect[1])
