"""Trajectory tracking: PID on speed (throttle / brake) + pure pursuit (steer).

The paper sends the selected trajectory "to the PID controller to actuate the steer,
throttle and brake". Here:

* longitudinal: ``a = a_ff + PID(v_des - v)`` with ``v_des`` / ``a_ff`` read from the
  trajectory's speed profile at ``t_offset + speed_preview``; ``a >= 0`` maps to
  ``throttle = a / max_accel``, ``a < 0`` to ``brake = -a / max_decel``; at (near)
  standstill with ``v_des ~ 0`` a holding brake is applied;
* lateral: pure pursuit from the footprint centre (the planned positions are centres) to
  the point of the trajectory (polyline of its ``x, y``) one look-ahead distance
  ``clip(lookahead_time v, min_lookahead, max_lookahead)`` ahead of the point closest to
  the vehicle (extended straight past the trajectory's end): arc curvature
  ``kappa = 2 sin(alpha) / l_d`` with ``alpha`` measured from the centre's velocity
  direction, converted to the bicycle's front-wheel angle (see :meth:`steer_angle`);
  ``steer = delta / max_steer``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .state import VehicleState
from .vehicle import Control, VehicleParams

from hbmp_bench.errors import ConfigError

__all__ = ["PID", "TrackerConfig", "TrajectoryTracker"]


class PID:
    """Scalar PID with a clamped integral (anti wind-up)."""

    def __init__(self, kp: float, ki: float = 0.0, kd: float = 0.0,
                 integral_limit: float = math.inf):
        if not all(math.isfinite(g) and g >= 0 for g in (kp, ki, kd)):
            raise ValueError(f"PID gains must be finite and >= 0, got {(kp, ki, kd)}")
        if not integral_limit > 0:
            raise ValueError(f"integral_limit must be > 0, got {integral_limit!r}")
        self.kp, self.ki, self.kd, self.integral_limit = kp, ki, kd, integral_limit
        self.reset()

    def reset(self) -> None:
        self.integral = 0.0
        self._prev: float | None = None

    def __call__(self, error: float, dt: float) -> float:
        """Control output for ``error`` over a step ``dt`` [s]."""
        lim = self.integral_limit
        self.integral = min(max(self.integral + error * dt, -lim), lim)
        deriv = 0.0 if self._prev is None or dt <= 0 else (error - self._prev) / dt
        self._prev = error
        return self.kp * error + self.ki * self.integral + self.kd * deriv


@dataclass(frozen=True)
class TrackerConfig:
    """Tracking gains.

    Attributes:
        kp_speed: proportional gain [(m/s^2) / (m/s)].
        ki_speed: integral gain [(m/s^2) / m].
        kd_speed: derivative gain [(m/s^2) / (m/s^2)].
        integral_limit: clamp of the speed-error integral [m].
        speed_preview: the speed target is read this far ahead of ``t_offset`` [s].
        lookahead_time: pure-pursuit look-ahead distance per unit speed [s].
        min_lookahead, max_lookahead: bounds of the look-ahead distance [m].
        hold_brake: brake applied at standstill when the target speed is ~0 ([0, 1]).
    """

    kp_speed: float = 1.0
    ki_speed: float = 0.2
    kd_speed: float = 0.0
    integral_limit: float = 3.0
    speed_preview: float = 0.1
    lookahead_time: float = 0.6
    min_lookahead: float = 3.0
    max_lookahead: float = 25.0
    hold_brake: float = 0.3

    def __post_init__(self):
        for name in ("kp_speed", "ki_speed", "kd_speed", "speed_preview"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ConfigError(f"TrackerConfig.{name} must be finite and >= 0, got {v!r}")
        for name in ("integral_limit", "lookahead_time", "min_lookahead", "max_lookahead"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"TrackerConfig.{name} must be finite and > 0, got {v!r}")
        if self.max_lookahead < self.min_lookahead:
            raise ConfigError("TrackerConfig.max_lookahead must be >= min_lookahead")
        if not 0.0 <= self.hold_brake <= 1.0:
            raise ConfigError(f"TrackerConfig.hold_brake must be in [0, 1], got {self.hold_brake!r}")


def lookahead_point_reference(xy: np.ndarray, p: np.ndarray, dist: float) -> np.ndarray:
    """Point ``dist`` [m] along polyline ``xy`` (T, 2) from its point closest to ``p``.

    The numpy form of the compiled :func:`.tracking_kernel.lookahead_point` that the tracker runs (the tests
    hold the two to the same floats)."""
    seg = np.diff(xy, axis=0)
    L = np.hypot(seg[:, 0], seg[:, 1])
    keep = L > 1e-6
    if not keep.any():  # (almost) standing trajectory: no direction information
        return xy[0].copy()
    seg, L = seg[keep], L[keep]
    starts = xy[:-1][keep]
    t = np.clip(((p - starts) * seg).sum(1) / (L * L), 0.0, 1.0)
    d = np.hypot(*(starts + t[:, None] * seg - p).T)
    j = int(np.argmin(d))
    cum = np.concatenate(([0.0], np.cumsum(L)))
    s_target = cum[j] + t[j] * L[j] + dist
    if s_target >= cum[-1]:  # extend along the last segment
        return starts[-1] + seg[-1] * (1.0 + (s_target - cum[-1]) / L[-1])
    k = int(np.searchsorted(cum, s_target, side="right") - 1)
    return starts[k] + seg[k] * ((s_target - cum[k]) / L[k])


class TrajectoryTracker:
    """Turns a planned trajectory into :class:`.vehicle.Control` commands.

    Args:
        vehicle: actuator limits and geometry of the tracked vehicle.
        cfg: gains.
    """

    def __init__(self, vehicle: VehicleParams = VehicleParams(),
                 cfg: TrackerConfig = TrackerConfig()):
        self.vehicle, self.cfg = vehicle, cfg
        self.pid = PID(cfg.kp_speed, cfg.ki_speed, cfg.kd_speed, cfg.integral_limit)

    def reset(self) -> None:
        self.pid.reset()

    def steer_angle(self, state: VehicleState, trajectory: np.ndarray) -> float:
        """Pure-pursuit front-wheel angle [rad] (not clipped) towards ``trajectory`` (T, >=2).

        The planned positions are footprint centres, so the pursuit runs from the centre: the
        arc tangent to ``state.yaw`` through the look-ahead point has curvature
        ``kappa = 2 sin(alpha) / l_d``; ``state.yaw`` must be the centre's direction of travel
        (the executor passes ``yaw + beta``, see ``BehaviorExecutor._course``), and the bicycle model's centre
        follows curvature ``kappa`` with ``tan(delta) = kappa L / sqrt(1 - (l_r kappa)^2)``.
        (Pursuing from the rear axle towards centre positions would see a flatter arc and
        steer about half of what a curve needs.)
        """
        c = self.cfg
        vp = self.vehicle
        ld = min(max(c.lookahead_time * state.v, c.min_lookahead), c.max_lookahead)
        from .tracking_kernel import lookahead_point  # numba loads on the first call

        tx, ty = lookahead_point(np.asarray(trajectory, float), state.x, state.y, ld)
        dx, dy = tx - state.x, ty - state.y
        dist = math.hypot(dx, dy)
        if dist < 1e-6:
            return 0.0
        alpha = math.atan2(dy, dx) - state.yaw
        kappa = 2.0 * math.sin(alpha) / dist
        lk = min(abs(vp.rear_to_cg * kappa), 0.99)
        return math.atan(kappa * vp.wheelbase / math.sqrt(1.0 - lk * lk))

    def control(self, state: VehicleState, trajectory: np.ndarray, times: np.ndarray,
                dt: float, t_offset: float = 0.0) -> Control:
        """Command for the next ``dt`` [s].

        Args:
            state: current vehicle state.
            trajectory: (T, 4) ``[x, y, yaw, v]`` planned trajectory.
            times: (T,) its time stamps [s] (``times[0]`` = when it was planned).
            dt: control period [s].
            t_offset: time elapsed since the trajectory was planned [s].
        """
        traj = np.asarray(trajectory, dtype=float)
        times = np.asarray(times, dtype=float)
        vp, c = self.vehicle, self.cfg
        t_des = times[0] + t_offset + c.speed_preview
        from .tracking_kernel import interp  # numba loads on the first call

        v_des = interp(t_des, times, traj[:, 3])
        a_ff = (interp(t_des + dt, times, traj[:, 3]) - v_des) / dt if dt > 0 else 0.0
        if v_des < 0.05 and state.v < 0.3:
            self.pid.reset()
            throttle, brake = 0.0, c.hold_brake
        else:
            a = a_ff + self.pid(v_des - state.v, dt)
            throttle = min(max(a / vp.max_accel, 0.0), 1.0)
            brake = min(max(-a / vp.max_decel, 0.0), 1.0)
        delta = self.steer_angle(state, traj)
        steer = min(max(delta / vp.max_steer, -1.0), 1.0)
        return Control(steer=steer, throttle=throttle, brake=brake)
