"""Sampling planner: shapes, cost terms against the paper's formulas, obstacles."""

import numpy as np
import pytest

from hbmp_bench.planning import (Obstacles, Path, PlannerConfig, PlanningProblem, VehicleState,
                                 plan)
from hbmp_bench.planning.planner import _sat_overlap

LANE = 3.5
XS = np.linspace(-100.0, 500.0, 121)


def lane(y):
    return Path(np.stack([XS, np.full_like(XS, y)], axis=1))


CURRENT, LEFT, RIGHT = lane(0.0), lane(LANE), lane(-LANE)


def car(x, y=0.0, v=0.0, yaw=0.0, length=4.6, width=1.9):
    return (x, y, yaw, v, length, width)


def obstacles(*rows):
    return Obstacles.from_rows(rows)


def problem(path=CURRENT, ego=None, v_ref=10.0, obs=(), limit=20.0):
    ego = VehicleState(0.0, 0.0, 0.0, 10.0) if ego is None else ego
    return PlanningProblem(ego, path, v_ref, limit, obstacles(*obs) if obs else Obstacles.empty())


# ---------------------------------------------------------------------------- structure
def test_result_shapes_and_start_state():
    cfg = PlannerConfig()
    r = plan(problem(ego=VehicleState(1.0, 2.0, 0.3, 10.0)), cfg)
    S, T = cfg.n_samples, cfg.n_steps + 1
    assert (S, T) == (65, 31)
    assert r.trajectories.shape == (S, T, 4)
    assert r.costs.shape == (S, 3) and r.total.shape == (S,) and r.feasible.shape == (S,)
    assert r.omega.shape == (S, T - 1) and r.frenet.shape == (S, T, 2)
    np.testing.assert_allclose(r.times, np.arange(T) * 0.1)
    np.testing.assert_allclose(r.trajectories[:, 0, :3], np.tile([1.0, 2.0, 0.3], (S, 1)))
    assert r.trajectory is r.trajectories[r.chosen] or np.array_equal(r.trajectory, r.trajectories[r.chosen])
    assert r.c_total == pytest.approx(r.total[r.chosen])
    np.testing.assert_allclose(r.total, r.costs @ [cfg.w_velocity, cfg.w_dist, cfg.w_obs])
    assert r.brake_index == S - 1 and r.collision_free and r.feasible.all()


def test_unicycle_rollout_consistency():
    r = plan(problem(ego=VehicleState(0.0, 2.0, 0.3, 10.0)))
    tr, w, dt = r.trajectories, r.omega, 0.1
    # x_{k+1} = x_k + v_k cos(psi_k + omega_k dt / 2) dt ; psi_{k+1} = psi_k + omega_k dt
    mid = tr[:, :-1, 2] + 0.5 * w * dt
    np.testing.assert_allclose(tr[:, 1:, 0], tr[:, :-1, 0] + tr[:, :-1, 3] * np.cos(mid) * dt)
    np.testing.assert_allclose(tr[:, 1:, 1], tr[:, :-1, 1] + tr[:, :-1, 3] * np.sin(mid) * dt)
    np.testing.assert_allclose(tr[:, 1:, 2], tr[:, :-1, 2] + w * dt)
    cfg = PlannerConfig()
    lim = np.minimum(np.minimum(cfg.yaw_rate_max, cfg.max_curvature * tr[:, :-1, 3]),
                     cfg.lat_accel_max / np.maximum(tr[:, :-1, 3], 1e-6))
    assert np.all(np.abs(w) <= lim + 1e-12)


def test_all_samples_converge_to_the_reference_lane():
    r = plan(problem(ego=VehicleState(0.0, 2.0, 0.3, 10.0)))
    e = r.frenet[:, :, 1]
    grid = slice(0, r.brake_index - 1)
    assert np.all(np.abs(e[grid, -1]) < 1.0)      # from 2 m (and heading away) to < 1 m in 3 s
    assert np.all(np.abs(e[grid, -1]) < np.abs(e[grid, 0]))
    # Frenet coordinates agree with a fresh projection
    xy = r.trajectories[:, :, :2].reshape(-1, 2)
    s, ee = CURRENT.frenet(xy)
    np.testing.assert_allclose(ee, e.ravel(), atol=1e-9)


def test_lane_change_samples_reach_the_left_lane():
    r = plan(problem(path=LEFT))
    assert r.trajectory[-1, 1] > 2.5 and r.frenet[r.chosen, -1, 1] > -1.0


# ---------------------------------------------------------------------------- cost terms
def test_c_velocity_matches_the_formula():
    cfg = PlannerConfig(v_window_time=0.0, accel=2.0)
    r = plan(problem(ego=VehicleState(0.0, 0.0, 0.0, 5.0), v_ref=7.0), cfg)
    num = den = 0.0
    for k in range(1, 31):  # hand computation of sum t^2 |v_ref - v(t)| / sum t^2
        t = 0.1 * k
        v = min(5.0 + 2.0 * t, 7.0)
        num += t * t * abs(7.0 - v)
        den += t * t
    n_grid = cfg.n_v * cfg.n_omega
    np.testing.assert_allclose(r.costs[:n_grid, 0], num / den, rtol=1e-12)
    np.testing.assert_allclose(r.trajectories[0, :11, 3], 5.0 + 2.0 * np.arange(11) * 0.1)
    # every sample: recompute from its own speed column
    t = r.times[1:]
    v = r.trajectories[:, 1:, 3]
    np.testing.assert_allclose(r.costs[:, 0], (t**2 * np.abs(7.0 - v)).sum(1) / (t**2).sum())


def test_c_dist_matches_the_formula():
    cfg = PlannerConfig(v_window_time=0.0)
    r = plan(problem(v_ref=10.0), cfg)
    n_grid = cfg.n_v * cfg.n_omega
    np.testing.assert_allclose(r.costs[:n_grid, 1], 1.0 / (1.0 + 30 * 10.0))
    v = r.trajectories[:, 1:, 3]
    np.testing.assert_allclose(r.costs[:, 1], 1.0 / (1.0 + np.abs(v).sum(1)))
    assert r.costs[r.brake_index, 1] > r.costs[0, 1]  # braking travels less


def test_c_velocity_prefers_reaching_v_ref():
    r = plan(problem(ego=VehicleState(0.0, 0.0, 0.0, 5.0), v_ref=7.0))
    v0 = r.trajectories[:, 0, 3]
    assert v0[r.chosen] == pytest.approx(v0[: r.brake_index - 1].max())
    assert r.costs[r.brake_index, 0] > r.costs[r.chosen, 0]


def test_c_obs_zero_without_obstacles_and_small_for_far_lanes():
    assert np.all(plan(problem()).costs[:, 2] == 0.0)
    r = plan(problem(obs=[car(15.0, y=2 * LANE + 1.0)]))  # two lanes away
    assert r.costs[:, 2].max() < 1e-3


def test_c_obs_grows_as_the_obstacle_gets_closer():
    chosen, lowest = [], []
    for gap in [80.0, 60.0, 45.0, 35.0]:
        r = plan(problem(obs=[car(gap, v=8.0)]))
        assert r.collision_free
        chosen.append(r.costs[r.chosen, 2])
        lowest.append(r.costs[:, 2].min())
    assert np.all(np.diff(chosen) > 0) and np.all(np.diff(lowest) > 0)
    # and closer laterally
    lat = [plan(problem(obs=[car(30.0, y=y, v=10.0)])).costs[0, 2] for y in (6.0, 4.5, 3.5, 2.5)]
    assert np.all(np.diff(lat) > 0)


def test_c_obs_hand_computed_single_obstacle():
    cfg = PlannerConfig(n_v=1, n_omega=1)
    # obstacle driving with the ego at the same speed, 30 m ahead, same lane
    r = plan(problem(obs=[car(30.0, v=10.0, length=4.0, width=2.0)]), cfg)
    g_lon = 30.0 - 0.5 * (cfg.length + 4.0)
    expected = np.exp(-g_lon / cfg.sigma_obs)  # g_lat = 0 at every step
    assert r.costs[0, 2] == pytest.approx(expected, rel=1e-5)
    # 1 m of lateral gap costs exp(-kappa_obs * 1 / sigma)
    y = 0.5 * (cfg.width + 2.0) + 1.0
    r = plan(problem(obs=[car(30.0, y=y, v=10.0, length=4.0, width=2.0)]), cfg)
    assert r.costs[0, 2] == pytest.approx(expected * np.exp(-cfg.kappa_obs / cfg.sigma_obs), rel=1e-4)


# ---------------------------------------------------------------------------- collisions
def _brute_overlap(a, b, n=60):
    """Dense-sampling overlap of two rectangles (cx, cy, yaw, length, width)."""
    def pts(r):
        u, v = np.meshgrid(np.linspace(-0.5, 0.5, n), np.linspace(-0.5, 0.5, n))
        lx, ly = u.ravel() * r[3], v.ravel() * r[4]
        c, s = np.cos(r[2]), np.sin(r[2])
        return np.stack([r[0] + c * lx - s * ly, r[1] + s * lx + c * ly], 1)

    def inside(p, r):
        c, s = np.cos(r[2]), np.sin(r[2])
        d = p - r[:2]
        return (np.abs(d @ [c, s]) <= r[3] / 2) & (np.abs(d @ [-s, c]) <= r[4] / 2)

    return bool(inside(pts(a), b).any() or inside(pts(b), a).any())


def test_separating_axis_against_brute_force():
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(400):
        a = np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi), rng.uniform(2, 5), rng.uniform(1, 2.5)])
        b = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi), rng.uniform(2, 5), rng.uniform(1, 2.5)])
        grow, shrink = b.copy(), b.copy()
        grow[3:] *= 1.03
        shrink[3:] *= 0.97
        truth = _brute_overlap(a, b)
        if truth != _brute_overlap(a, grow) or truth != _brute_overlap(a, shrink):
            continue  # too close to touching for the sampled reference
        got = _sat_overlap(np.array([b[0]]), np.array([b[1]]), np.cos(a[2]), np.sin(a[2]), a[3] / 2,
                           a[4] / 2, np.cos(b[2]), np.sin(b[2]), b[3] / 2, b[4] / 2)[0]
        assert got == truth
        checked += 1
    assert checked > 300


def test_adjacent_lane_traffic_is_feasible():
    r = plan(problem(obs=[car(0.0, y=LANE, v=10.0), car(10.0, y=-LANE, v=10.0)]))
    assert r.feasible[: r.brake_index - 1].all() and r.collision_free


def test_blocked_lane_slows_down():
    r = plan(problem(obs=[car(25.0)]))  # stopped car 25 m ahead at 10 m/s
    n_grid = r.brake_index - 1
    assert not r.feasible[:n_grid].any()  # keeping 10 m/s hits it within 3 s
    assert r.collision_free and r.chosen in (r.brake_index - 1, r.brake_index)
    v = r.trajectory[:, 3]
    assert v[-1] <= 1.0 + 1e-9 and np.all(np.diff(v) <= 1e-12)  # 10 m/s at >= 3 m/s^2 for 3 s


def test_a_close_follower_does_not_keep_the_ego_from_braking_for_a_queue():
    """Recorded in nocrash-dense (Town04 episode 2, 119 s): a stopped car 25 m ahead, a car 15 m behind at
    9.6 m/s. Predicted at constant speed the follower hit every slowing sample, nothing was feasible, and the
    cheapest sample kept 13 m/s into the queue (``hbmp`` ran into it at 10 m/s three seconds later)."""
    obs = [car(25.0), car(-15.0, y=-0.3, v=9.6)]
    r = plan(problem(ego=VehicleState(0.0, 0.0, 0.0, 10.5), v_ref=13.0, obs=obs))
    assert r.collision_free and r.chosen in (r.brake_index - 1, r.brake_index) and r.trajectory[-1, 3] < 2.0
    alone = plan(problem(ego=VehicleState(0.0, 0.0, 0.0, 10.5), v_ref=13.0, obs=obs[:1]))
    assert (r.costs[:, 2] > alone.costs[:, 2]).all()  # the follower still counts in c_obs
    old = plan(problem(ego=VehicleState(0.0, 0.0, 0.0, 10.5), v_ref=13.0, obs=obs),
               PlannerConfig(ignore_followers=False, infeasible_fallback="min_cost"))
    assert not old.collision_free and old.trajectory[-1, 3] > 10.5  # the defect this setting removes
    latest = plan(problem(ego=VehicleState(0.0, 0.0, 0.0, 10.5), v_ref=13.0, obs=obs),
                  PlannerConfig(ignore_followers=False))
    assert not latest.collision_free  # the default fallback alone: the latest contact, on a queue ahead
    assert latest.contact_time[latest.chosen] == latest.contact_time.max()


def test_only_a_follower_in_the_egos_line_is_left_out_of_the_collision_check():
    from hbmp_bench.planning.obstacle_kernels import followers

    # (s, e, theta) of: behind in line, behind in the next lane, alongside, behind oncoming, ahead, just touching
    so = np.array([-15.0, -15.0, -2.0, -15.0, 15.0, -4.5])
    eo = np.array([0.3, 3.5, 0.0, 0.0, 0.0, 0.0])
    theta = np.array([0.1, 0.0, 0.0, np.pi, 0.0, 0.0])
    size = np.full(6, 4.6), np.full(6, 1.9)
    assert followers(so, eo, theta, *size, 0.0, 0.0, 4.6, 1.9).tolist() == [True, False, False, False, False, False]
    # a lane change under way: the ego 3.5 m off the (target lane's) path, a car behind in the target lane
    assert not followers(so[:1], np.zeros(1), theta[:1], *(a[:1] for a in size), 0.0, -3.5, 4.6, 1.9)[0]
    # that car stays in the check: cutting in front of it at 10 m/s when it closes at 15 is infeasible
    r = plan(problem(path=LEFT, obs=[car(-8.0, y=LANE, v=15.0)]))
    assert not r.feasible[: r.brake_index - 1].all()


def test_unavoidable_obstacle_is_flagged():
    p = problem(obs=[car(8.0)])  # 3 m gap at 10 m/s: even the full brake hits it
    r = plan(p)  # the default fallback: the latest first contact, here the full brake's
    assert not r.feasible.any() and not r.collision_free
    assert np.isfinite(r.contact_time).all() and r.contact_time[r.chosen] == r.contact_time.max()
    assert r.chosen == r.brake_index and r.trajectory[-1, 3] == 0.0
    assert (r.contact_time == r.contact_time[0]).all()  # every sample meets it at 0.4 s: the slowest there
    rb = plan(p, PlannerConfig(infeasible_fallback="brake"))
    assert rb.chosen == rb.brake_index and not rb.collision_free
    rm = plan(p, PlannerConfig(infeasible_fallback="min_cost"))
    assert not rm.collision_free
    assert rm.chosen == int(np.argmin(rm.total)) or rm.total[rm.chosen] <= rm.total.min() + 1e-3
    assert rm.trajectory[-1, 3] > 0.0  # the cheapest keeps going: the defect the default removes


def test_a_threat_from_behind_is_not_met_by_braking():
    """Recorded in ``hbmp-s``'s Town03 Navigation-dynamic episode 34 (``hbmp`` suite): a lane change at
    2 m/s, the ego turned towards the new lane, the queued car it leaves behind accelerating into the gap
    (5.5-5.8 m/s at the contact). Nothing is collision-free; the full brake stopped the ego in front of it and it
    ran into the ego. The latest first contact keeps moving and puts the contact off."""
    obs = [car(-7.0, v=5.5)]  # in the lane the ego leaves, 2.4 m between the two
    ego = VehicleState(0.0, 1.5, 0.3, 2.0)  # 1.5 m into the change, 17 degrees towards the left lane
    p = problem(ego=ego, path=LEFT, v_ref=5.0, obs=obs)
    r = plan(p, PlannerConfig(ignore_followers=False))
    assert not r.collision_free and np.isfinite(r.contact_time).all()
    assert r.contact_time[r.chosen] > r.contact_time[r.brake_index]
    assert r.trajectory[-1, 3] > 2.0  # it drives away from the threat
    rb = plan(p, PlannerConfig(ignore_followers=False, infeasible_fallback="brake"))
    assert rb.chosen == rb.brake_index


@pytest.mark.parametrize("x_obstacle, met_ahead", [(3.0, True), (-3.0, False)])
def test_a_contact_every_sample_shares_is_braked_for_only_when_it_is_ahead(x_obstacle, met_ahead):
    """A car in the lane to the left already touches the ego's inflated footprint, so every sample meets it
    at the first step. Ahead of the ego's centre, braking softens the contact: the slowest sample. Behind
    it, braking would stop the ego in the car's way: the cheapest of the tied samples."""
    p = problem(ego=VehicleState(0.0, 0.0, 0.0, 3.0), v_ref=5.0, obs=[car(x_obstacle, y=2.0, v=3.0)])
    r = plan(p)
    assert not r.feasible.any() and (r.contact_time == r.times[1]).all()
    impact_speed = r.trajectories[:, 1, 3]
    if met_ahead:
        assert impact_speed[r.chosen] == impact_speed.min()
    else:
        assert r.total[r.chosen] <= r.total.min() + PlannerConfig().tie_tolerance
        assert r.trajectory[-1, 3] > 3.0  # it drives on towards v_ref


def test_met_ahead_reads_the_touching_obstacles_centre_along_the_heading():
    from hbmp_bench.planning.planner import met_ahead

    cfg = PlannerConfig()
    pose = np.array([0.0, 0.0, np.pi / 2, 5.0])  # heading +y
    touching_ahead = obstacles(car(1.0, y=3.0, yaw=np.pi / 2))
    assert met_ahead(pose, 0.0, touching_ahead, cfg)
    assert not met_ahead(pose, 0.0, obstacles(car(1.0, y=-3.0, yaw=np.pi / 2)), cfg)  # behind
    assert not met_ahead(pose, 0.0, obstacles(car(0.0, y=20.0)), cfg)  # ahead but far: no contact
    assert not met_ahead(pose, 0.0, Obstacles.empty(), cfg)
    # predicted as the collision check predicts: 10 m behind at 10 m/s closing, touching 0.6 s on
    behind_closing = obstacles(car(0.0, y=-10.0, yaw=np.pi / 2, v=10.0))
    assert not met_ahead(pose, 0.6, behind_closing, cfg)
    assert met_ahead(pose, 1.2, behind_closing, cfg)  # 2 m past the ego's centre by then


def test_obstacle_ahead_makes_keep_costlier_than_change_left():
    obs = [car(25.0, v=5.0)]  # slower car 25 m ahead in the current lane
    costs = {name: plan(problem(path=p, obs=obs)).c_total
             for name, p in [("left", LEFT), ("keep", CURRENT), ("right", RIGHT)]}
    assert costs["keep"] > costs["left"]
    assert costs["keep"] > costs["right"]
    # a car alongside in the left lane turns it around
    obs2 = obs + [car(3.0, y=LANE, v=10.0)]
    r_left = plan(problem(path=LEFT, obs=obs2))
    r_keep = plan(problem(path=CURRENT, obs=obs2))
    assert r_left.c_total > r_keep.c_total or not r_left.collision_free


def test_curved_reference():
    R = 40.0
    a = np.linspace(-np.pi / 2, np.pi / 2, 181)
    path = Path(np.stack([R * np.cos(a), R + R * np.sin(a)], axis=1))  # left turn, starts at (0, 0)
    r = plan(PlanningProblem(VehicleState(0.0, 0.0, 0.0, 8.0), path, 8.0, 15.0))
    e = r.frenet[r.chosen, :, 1]
    assert np.all(np.abs(e) < 0.05)  # stays on the arc
    np.testing.assert_allclose(r.omega[r.chosen, 10:], 8.0 / R, rtol=0.03)


# ---------------------------------------------------------------------------- config
@pytest.mark.parametrize("kw", [dict(horizon=0.25), dict(dt=0.0), dict(n_v=0), dict(n_omega=2.5),
                                dict(w_obs=-1.0), dict(k_e=0.0), dict(accel=float("nan")),
                                dict(infeasible_fallback="stop"), dict(lat_accel_max=0.0),
                                dict(length=-1.0)])
def test_config_validation(kw):
    with pytest.raises(ValueError):
        PlannerConfig(**kw)


def test_problem_validation():
    ego = VehicleState(0.0, 0.0, 0.0, 1.0)
    with pytest.raises(ValueError):
        PlanningProblem(ego, CURRENT, -1.0, 10.0)
    with pytest.raises(ValueError):
        PlanningProblem(ego, CURRENT, 1.0, 0.0)
    with pytest.raises(ValueError):
        PlanningProblem(ego, XS, 1.0, 10.0)
    with pytest.raises(ValueError):
        Obstacles(x=[0.0], y=[0.0, 1.0], yaw=[0.0], v=[0.0], length=[1.0], width=[1.0])
    with pytest.raises(ValueError):
        VehicleState(0.0, 0.0, 0.0, -1.0)


def test_short_path_is_extended_straight():
    short = Path([[0.0, 1.0], [20.0, 1.0]])
    r = plan(PlanningProblem(VehicleState(15.0, 0.0, 0.0, 10.0), short, 10.0, 20.0))
    assert r.trajectory[-1, 0] > 40.0  # well past the end of the path
    assert abs(r.trajectory[-1, 1] - 1.0) < 0.3  # converged onto the extended centerline
    np.testing.assert_allclose(r.frenet[r.chosen, -1, 0], r.trajectory[-1, 0], atol=0.05)


def test_compile_kernels_compiles_the_signature_every_plan_uses():
    from hbmp_bench.planning import plan_kernel
    from hbmp_bench.planning.planner import compile_kernels

    compile_kernels()
    compiled = list(plan_kernel.plan_samples.signatures)
    assert len(compiled) == 1
    curved = Path(np.stack([XS, 0.002 * XS**2], axis=1))  # another path, obstacles, ego, config
    plan(PlanningProblem(VehicleState(3, 1, 0.2, 0), curved, v_ref=5, speed_limit=8, obstacles=obstacles(car(20.0))),
         PlannerConfig(n_v=3, n_omega=5, horizon=2.0))
    plan(problem(v_ref=0.0))
    assert plan_kernel.plan_samples.signatures == compiled  # nothing more was compiled
