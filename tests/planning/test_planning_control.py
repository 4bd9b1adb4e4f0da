"""Control law, omega limits, speed profile and the behavior reference speed."""

import math

import numpy as np
import pytest

from hbmp_bench.planning import (Behavior, BehaviorConfig, control_law, linear_speed_profile,
                                 omega_limit, reference_speed)


def test_control_law_straight_path_hand_computed():
    # kappa = 0: omega = -k_theta |v| theta - k_e v sin(theta)/theta e
    v, th, e, kt, ke = 10.0, 0.2, 1.0, 0.5, 0.1
    expected = -kt * 10.0 * 0.2 - ke * 10.0 * (math.sin(0.2) / 0.2) * 1.0
    assert expected == pytest.approx(-1.99335, abs=1e-5)
    assert control_law(v, 0.0, e, th, kt, ke) == pytest.approx(expected, rel=1e-12)


def test_control_law_curved_hand_computed():
    v, kap, e, th, kt, ke = 8.0, 0.05, -0.4, -0.1, 0.7, 0.12
    expected = (v * kap * math.cos(th) / (1 - kap * e) - kt * abs(v) * th
                - ke * v * math.sin(th) / th * e)
    assert control_law(v, kap, e, th, kt, ke) == pytest.approx(expected, rel=1e-12)
    # on the lane and aligned: pure feed-forward v * kappa
    assert control_law(v, kap, 0.0, 0.0, kt, ke) == pytest.approx(v * kap)


def test_control_law_theta_to_zero_limit():
    v, e, ke = 5.0, 2.0, 0.1
    at0 = control_law(v, 0.0, e, 0.0, 0.4, ke)
    assert at0 == pytest.approx(-ke * v * e)  # sin(theta)/theta -> 1
    near = control_law(v, 0.0, e, 1e-9, 0.4, ke)
    assert near == pytest.approx(at0, abs=1e-8)
    assert np.isfinite(control_law(v, 0.0, e, np.array([0.0, -0.0, 1e-300]), 0.4, ke)).all()


def test_control_law_signs_converge():
    # left of the lane (e > 0) -> turn right; heading left of the lane (theta > 0) -> turn right
    assert control_law(10.0, 0.0, 1.0, 0.0, 0.7, 0.12) < 0
    assert control_law(10.0, 0.0, 0.0, 0.2, 0.7, 0.12) < 0
    assert control_law(10.0, 0.0, -1.0, -0.2, 0.7, 0.12) > 0


def test_control_law_denominator_guard_and_broadcast():
    # 1 - kappa e = 0 (at the centre of curvature) and negative: finite, guarded to 0.1
    w = control_law(np.array([5.0, 5.0]), 0.1, np.array([10.0, 20.0]), 0.0, 0.7, 0.0)
    np.testing.assert_allclose(w, 5.0 * 0.1 / 0.1)
    out = control_law(np.ones((4, 1)), np.zeros(3), np.zeros(3), np.zeros(3), 0.7, 0.1)
    assert out.shape == (4, 3)


def test_omega_limit():
    lim = omega_limit(np.array([0.0, 1.0, 10.0, 20.0]), yaw_rate_max=0.6, max_curvature=0.2,
                      lat_accel_max=4.0)
    np.testing.assert_allclose(lim, [0.0, 0.2, 0.4, 0.2])
    assert omega_limit(10.0, 0.6, 0.2) == pytest.approx(0.6)


def test_linear_speed_profile():
    t = np.arange(6) * 0.5
    v = linear_speed_profile(np.array([5.0, 10.0, 3.0]), np.array([7.0, 7.0, 3.0]), t,
                             accel=2.0, decel=3.0)
    np.testing.assert_allclose(v[0], [5, 6, 7, 7, 7, 7])
    np.testing.assert_allclose(v[1], [10, 8.5, 7, 7, 7, 7])
    np.testing.assert_allclose(v[2], 3.0)
    assert linear_speed_profile(0.0, 1.0, t, 1.0, 1.0).shape == (6,)


def test_behavior_order_matches_paper():
    assert [b.name for b in Behavior] == ["SPEED_UP", "SPEED_DOWN", "CHANGE_LEFT",
                                          "CHANGE_RIGHT", "KEEP"]
    assert [int(b) for b in Behavior] == [0, 1, 2, 3, 4]


@pytest.mark.parametrize("b, v, limit, expected", [
    (Behavior.SPEED_UP, 15.0, 30.0, 18.0),      # +20 %
    (Behavior.SPEED_UP, 5.0, 30.0, 7.0),        # min step 2 m/s
    (Behavior.SPEED_UP, 0.0, 30.0, 2.0),        # from standstill
    (Behavior.SPEED_UP, 13.0, 13.89, 13.89),    # capped to the limit
    (Behavior.SPEED_DOWN, 20.0, 30.0, 13.0),    # -35 %
    (Behavior.SPEED_DOWN, 13.89, 13.89, 9.0285),
    (Behavior.SPEED_DOWN, 8.0, 30.0, 4.5),      # min step 3.5 m/s
    (Behavior.SPEED_DOWN, 3.0, 30.0, 0.0),      # not below 0
    (Behavior.SPEED_DOWN, 20.0, 13.89, 13.0),   # above the limit: -35 %, at most the limit
    (Behavior.SPEED_DOWN, 30.0, 13.89, 13.89),
    (Behavior.CHANGE_LEFT, 9.0, 30.0, 9.0),
    (Behavior.CHANGE_RIGHT, 9.0, 30.0, 9.0),
    (Behavior.KEEP, 9.0, 30.0, 9.0),
    (Behavior.KEEP, 0.0, 30.0, 0.0),            # keep = current velocity, no creep
    (4, 9.0, 30.0, 9.0),                        # plain ints accepted
])
def test_reference_speed(b, v, limit, expected):
    assert reference_speed(b, v, limit) == pytest.approx(expected)


def test_reference_speed_config_and_validation():
    cfg = BehaviorConfig(speed_up_frac=0.5, speed_up_min_step=0.0)
    assert reference_speed(Behavior.SPEED_UP, 10.0, 30.0, cfg) == pytest.approx(15.0)
    assert reference_speed(Behavior.SPEED_DOWN, 10.0, 30.0, cfg) == pytest.approx(6.5)  # speed_down unchanged
    cfg = BehaviorConfig(speed_down_frac=0.2, speed_down_min_step=2.0)
    assert reference_speed(Behavior.SPEED_DOWN, 15.0, 30.0, cfg) == pytest.approx(12.0)
    assert reference_speed(Behavior.SPEED_DOWN, 9.0, 30.0, BehaviorConfig(speed_down_frac=1.0)) == 0.0
    for bad in ({"speed_up_frac": 0.0}, {"speed_up_frac": 1.0}, {"speed_down_frac": 0.0},
                {"speed_down_frac": 1.01}, {"speed_up_min_step": -1.0}, {"speed_down_min_step": -0.1},
                {"speed_down_min_step": float("nan")}, {"speed_down_min_step": float("inf")},
                {"min_lane_change_speed": -1.0}):
        with pytest.raises(ValueError):
            BehaviorConfig(**bad)
    with pytest.raises(ValueError):
        reference_speed(Behavior.KEEP, 1.0, 0.0)
    with pytest.raises(ValueError):
        reference_speed(7, 1.0, 10.0)


def test_speed_step_sizes():
    cfg = BehaviorConfig()
    assert cfg.speed_step(Behavior.SPEED_UP, 15.0) == pytest.approx(3.0)       # 20 %
    assert cfg.speed_step(Behavior.SPEED_UP, 0.0) == pytest.approx(2.0)        # min 2 m/s
    assert cfg.speed_step(Behavior.SPEED_DOWN, 20.0) == pytest.approx(7.0)     # 35 %
    assert cfg.speed_step(Behavior.SPEED_DOWN, 5.0) == pytest.approx(3.5)      # min 3.5 m/s
    for b in (Behavior.KEEP, Behavior.CHANGE_LEFT, Behavior.CHANGE_RIGHT):
        assert cfg.speed_step(b, 10.0) == 0.0


def test_a_chain_of_speed_down_steps_stops_in_few_decisions():
    """From 50 km/h each v_ref step is at least decel * 1 s of the planner's profile (3 m/s), so a
    one-second behavior brakes all the time; v_ref reaches 0 within four decisions."""
    cfg, v, refs = BehaviorConfig(), 13.89, []
    while v > 0.0:
        v = reference_speed(Behavior.SPEED_DOWN, v, 13.89, cfg)
        refs.append(v)
    assert refs == pytest.approx([9.0285, 5.5285, 2.0285, 0.0])
    assert all(cfg.speed_step(Behavior.SPEED_DOWN, u) >= 3.0 for u in (13.89, *refs[:-1]))
    v, ups = 0.0, []
    while v < 13.89:  # speed_up keeps its finer 20 % / 2 m/s steps
        v = reference_speed(Behavior.SPEED_UP, v, 13.89, cfg)
        ups.append(v)
    assert ups == pytest.approx([2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 13.89])
