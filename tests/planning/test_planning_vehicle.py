"""Kinematic bicycle model, PID and the trajectory tracker."""

import math

import numpy as np
import pytest

from hbmp_bench.planning import (PID, Control, TrackerConfig, TrajectoryTracker, VehicleParams,
                                 VehicleState, step)


def test_throttle_and_brake():
    vp = VehicleParams(max_accel=3.0, max_decel=8.0)
    s = VehicleState(0.0, 0.0, 0.0, 0.0)
    for _ in range(10):
        s = step(s, Control(throttle=1.0), 0.1, vp)
    assert s.v == pytest.approx(3.0)
    assert s.x == pytest.approx(0.5 * 3.0 * 1.0**2, rel=0.02)
    s = step(s, Control(brake=1.0), 1.0, vp)
    assert s.v == 0.0  # never reverses
    assert s.y == 0.0 and s.yaw == 0.0


def test_steering_rate_limit_and_turn_radius():
    vp = VehicleParams(wheelbase=2.8, rear_to_cg=1.4, max_steer=0.6, max_steer_rate=1.0)
    s = VehicleState(0.0, 0.0, 0.0, 10.0)
    s = step(s, Control(steer=1.0), 0.1, vp)
    assert s.steer == pytest.approx(0.1)  # 1 rad/s for 0.1 s
    for _ in range(10):
        s = step(s, Control(steer=0.5), 0.1, vp)
    assert s.steer == pytest.approx(0.3)
    # steady yaw rate of the CG-referenced bicycle
    s2 = step(s, Control(steer=0.5), 0.1, vp)
    beta = math.atan(0.5 * math.tan(0.3))
    expected = 10.0 * math.cos(beta) * math.tan(0.3) / 2.8
    assert math.remainder(s2.yaw - s.yaw, 2 * math.pi) / 0.1 == pytest.approx(expected, rel=1e-6)
    # positive steer turns left (counter-clockwise)
    assert s2.y > 0


def test_vehicle_validation():
    with pytest.raises(ValueError):
        Control(steer=1.5)
    with pytest.raises(ValueError):
        Control(throttle=-0.1)
    with pytest.raises(ValueError):
        VehicleParams(wheelbase=0.0)
    with pytest.raises(ValueError):
        VehicleParams(rear_to_cg=5.0)
    with pytest.raises(ValueError):
        step(VehicleState(0, 0, 0, 1), Control(), -0.1)


def test_pid():
    pid = PID(2.0, 1.0, 0.5, integral_limit=1.0)
    assert pid(1.0, 0.1) == pytest.approx(2.0 + 0.1)  # no derivative on the first call
    assert pid(1.0, 0.1) == pytest.approx(2.0 + 0.2)
    for _ in range(50):
        pid(1.0, 0.1)
    assert pid.integral == pytest.approx(1.0)  # clamped
    pid.reset()
    assert pid.integral == 0.0


def _straight_traj(v, n=31, dt=0.1, y=0.0, accel=0.0):
    t = np.arange(n) * dt
    vv = v + accel * t
    x = np.concatenate([[0.0], np.cumsum(vv[:-1] * dt)])
    return np.stack([x, np.full(n, y), np.zeros(n), vv], axis=1), t


def test_tracker_straight_and_speed():
    tr = TrajectoryTracker()
    traj, t = _straight_traj(10.0, accel=1.0)
    c = tr.control(VehicleState(0.0, 0.0, 0.0, 10.0), traj, t, 0.1)
    assert c.steer == pytest.approx(0.0, abs=1e-9)
    assert c.throttle > 0 and c.brake == 0
    traj, t = _straight_traj(5.0)
    c = tr.control(VehicleState(0.0, 0.0, 0.0, 10.0), traj, t, 0.1)
    assert c.brake > 0 and c.throttle == 0
    # standing target, standing car: hold brake
    traj = np.zeros((31, 4))
    c = tr.control(VehicleState(0.0, 0.0, 0.0, 0.0), traj, t, 0.1)
    assert c.brake == TrackerConfig().hold_brake and c.steer == 0.0


def test_tracker_steers_towards_the_trajectory():
    tr = TrajectoryTracker()
    traj, t = _straight_traj(10.0, y=2.0)  # trajectory 2 m to the left
    assert tr.control(VehicleState(0.0, 0.0, 0.0, 10.0), traj, t, 0.1).steer > 0
    traj, t = _straight_traj(10.0, y=-2.0)
    assert tr.control(VehicleState(0.0, 0.0, 0.0, 10.0), traj, t, 0.1).steer < 0


def test_closed_loop_tracks_a_straight_line():
    vp = VehicleParams()
    tr = TrajectoryTracker(vp)
    s = VehicleState(0.0, 1.0, 0.1, 8.0)
    for _ in range(100):
        t = np.arange(31) * 0.1
        xs = s.x + np.linspace(0, 30 * 0.1 * 10.0, 31)
        traj = np.stack([xs, np.zeros(31), np.zeros(31), np.full(31, 10.0)], axis=1)
        s = step(s, tr.control(s, traj, t, 0.1), 0.1, vp)
    assert abs(s.y) < 0.05 and abs(s.yaw) < 0.01 and s.v == pytest.approx(10.0, abs=0.1)
