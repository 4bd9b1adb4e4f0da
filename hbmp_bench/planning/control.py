"""Lane-following control law and speed profile of the HBMP motion planner.

The control law (paper eq. "control", from Paden et al. 2016) gives the angular velocity
that makes a unicycle converge to a reference path in curvilinear coordinates::

    omega = v kappa cos(theta_e) / (1 - kappa e)
            - (k_theta |v|) theta_e
            - (k_e v sin(theta_e) / theta_e) e

with ``sin(theta_e) / theta_e -> 1`` as ``theta_e -> 0`` (``np.sinc(theta_e / pi)``).
On a straight path, in terms of travelled distance, the linearised error obeys
``e'' + k_theta e' + k_e e = 0``; ``k_theta = 2 sqrt(k_e)`` is critically damped.

All functions are vectorised (numpy broadcasting) and unit-consistent:
``v`` [m/s], ``kappa`` [1/m], ``e`` [m], ``theta_e`` [rad], ``k_theta`` [1/m],
``k_e`` [1/m^2], ``omega`` [rad/s], ``t`` [s], accelerations [m/s^2].
"""

from __future__ import annotations

import numpy as np

__all__ = ["control_law", "omega_limit", "linear_speed_profile"]


def control_law(v, kappa, e, theta_e, k_theta: float, k_e: float, min_denominator: float = 0.1):
    """Angular velocity [rad/s] that drives ``(e, theta_e)`` to zero.

    Args:
        v: speed [m/s].
        kappa: reference curvature at the projection [1/m] (left turn positive).
        e: lateral error [m] (left positive).
        theta_e: heading error [rad] in (-pi, pi].
        k_theta: heading gain [1/m] (multiplies ``|v|``).
        k_e: lateral gain [1/m^2] (multiplies ``v``).
        min_denominator: guard for ``1 - kappa e``: it is clipped to at least this value
            (it reaches 0 at the centre of curvature and is negative beyond it, where the
            curvilinear frame is singular).

    Returns:
        ``omega`` broadcast over the inputs.
    """
    denom = np.maximum(1.0 - kappa * e, min_denominator)
    return (
        v * kappa * np.cos(theta_e) / denom
        - (k_theta * np.abs(v)) * theta_e
        - (k_e * v * np.sinc(theta_e / np.pi)) * e
    )


def omega_limit(v, yaw_rate_max: float, max_curvature: float, lat_accel_max: float = np.inf):
    """Largest admissible ``|omega|`` [rad/s] at speed ``v`` [m/s].

    ``min(yaw_rate_max, max_curvature |v|, lat_accel_max / |v|)``: the yaw-rate limit, the
    steering (minimum turning radius) limit and a lateral-acceleration limit.
    """
    av = np.abs(np.asarray(v, dtype=float))
    lim = np.minimum(yaw_rate_max, max_curvature * av)
    if np.isfinite(lat_accel_max):
        lim = np.minimum(lim, lat_accel_max / np.maximum(av, 1e-6))
    return lim


def linear_speed_profile(v0, v_ref, t, accel: float, decel: float):
    """Linear-acceleration speed profile from ``v0`` towards ``v_ref``.

    ``v(t) = v0 + clip(v_ref - v0, -decel t, accel t)``: constant acceleration ``accel``
    (or deceleration ``decel``) until ``v_ref`` is reached, then constant.

    Args:
        v0: initial speed(s) [m/s], shape (S,) or scalar.
        v_ref: target speed(s) [m/s], broadcastable to ``v0``.
        t: times [s], shape (T,), ``t >= 0``.
        accel, decel: positive acceleration / deceleration magnitudes [m/s^2] (scalars or
            broadcastable to ``v0``).

    Returns:
        ``(S, T)`` speeds [m/s] (or ``(T,)`` for scalar ``v0``).
    """
    v0 = np.asarray(v0, dtype=float)
    t = np.asarray(t, dtype=float)
    dv = np.asarray(v_ref, dtype=float) - v0
    acc = np.asarray(accel, dtype=float)
    dec = np.asarray(decel, dtype=float)
    tt = t if v0.ndim == 0 else t[None, :]
    dv = dv if np.ndim(dv) == 0 else dv[..., None]
    acc = acc if acc.ndim == 0 else acc[..., None]
    dec = dec if dec.ndim == 0 else dec[..., None]
    v0e = v0 if v0.ndim == 0 else v0[..., None]
    return v0e + np.clip(dv, -dec * tt, acc * tt)
