"""The planner's closed-loop roll-out, compiled with numba.

One planning call rolls S = 65 samples forward for 30 steps. The loop is sequential in time
(each step re-projects every sample on the reference), so vectorising over samples leaves
~40 numpy calls of 65 elements per step; their per-call overhead, not arithmetic, was 60 % of
a planning call (~1.7 of 2.9 ms). :func:`roll_out` runs the same arithmetic as scalar loops
compiled to machine code (~40x faster). It stays numpy-only code: with ``NUMBA_DISABLE_JIT=1``
it runs as plain Python, which the tests use to check the compiled and interpreted versions
agree.

The windowed projection searches only segments ``-n_back..+n_ahead`` around the segment of a
predicted arc length, on a path resampled at uniform arc-length steps
(:meth:`.frame.Path.uniform_segments`, :class:`.frame.UniformSegments`).

numba is imported here only: the planner imports this module inside :func:`.planner.plan`, so
that importing the planning package does not load numba.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["roll_out"]

#: Guard of ``1 - kappa e`` in the control law (see :func:`.control.control_law`).
MIN_DENOMINATOR = 0.1


@njit(cache=True, nogil=True)
def _project(px, py, s_hint, n_back, n_ahead, x0, y0, tx, ty, chord, s, s_per_m, heading, kappa, dh,
             dk, inv_ds):
    """``(s, e, heading, kappa)`` of one point: nearest of the segments around ``s_hint``."""
    nseg = len(chord)
    base = int((s_hint - s[0]) * inv_ds)  # truncation toward zero, as numpy's astype(intp)
    best_d2 = np.inf
    best_i = 0
    best_c = 0.0
    best_cross = 0.0
    for off in range(-n_back, n_ahead + 1):
        i = min(max(base + off, 0), nseg - 1)
        a = px - x0[i]
        b = py - y0[i]
        along = a * tx[i] + b * ty[i]
        cross = b * tx[i] - a * ty[i]
        c = min(max(along, 0.0), chord[i])
        d2 = (along - c) * (along - c) + cross * cross
        if d2 < best_d2:  # strict: the first minimum wins, as argmin
            best_d2, best_i, best_c, best_cross = d2, i, c, cross
    i = best_i
    frac = best_c / chord[i]
    return (s[i] + best_c * s_per_m[i], math.copysign(math.sqrt(best_d2), best_cross),
            heading[i] + frac * dh[i], kappa[i] + frac * dk[i])


@njit(cache=True, nogil=True)
def roll_out(x, y, yaw, s0, e0, th0, k0, V, KTH, KE, LIM, w_off, hold, dt, n_back, n_ahead,
             x0, y0, tx, ty, chord, s, s_per_m, heading, kappa, dh, dk, inv_ds):
    """Roll S samples forward under the lane-converging control law (kinematic unicycle).

    Args:
        x, y, yaw: start pose [m, m, rad]; ``s0, e0, th0, k0``: its projection on the
            reference (arc length [m], lateral error [m], heading error [rad], curvature [1/m]).
        V: (T, S) speed of each sample at each time [m/s], ``T = n_steps + 1``.
        KTH, KE: (T, S) control-law gains [1/m, 1/m^2]; LIM: (T, S) |omega| limit [rad/s].
        w_off: (S,) offset added to omega for the first ``hold`` steps [rad/s].
        dt: step [s]; ``n_back, n_ahead``: projection window [segments].
        x0 ... inv_ds: the reference's :class:`.frame.UniformSegments`.

    Returns:
        ``(X, Y, PSI, SS, EE, W)``: (T, S) poses [m, m, rad (continuous)] and Frenet
        coordinates [m] (row 0 = start), and (T - 1, S) applied omega [rad/s].
    """
    T, S = V.shape
    n = T - 1
    X = np.empty((T, S)); Y = np.empty((T, S)); PSI = np.empty((T, S))
    SS = np.empty((T, S)); EE = np.empty((T, S)); W = np.empty((n, S))
    half_dt = 0.5 * dt
    for j in range(S):
        px, py, psi = x, y, yaw
        sj, ej, th, kap = s0, e0, th0, k0
        X[0, j], Y[0, j], PSI[0, j], SS[0, j], EE[0, j] = px, py, psi, sj, ej
        for k in range(n):
            v = V[k, j]
            denom = max(1.0 - kap * ej, MIN_DENOMINATOR)
            sinc = math.sin(th) / th if th != 0.0 else 1.0
            w = (v * kap * math.cos(th) / denom - (KTH[k, j] * abs(v)) * th
                 - (KE[k, j] * v * sinc) * ej)
            if k < hold:
                w += w_off[j]
            lim = LIM[k, j]
            w = min(max(w, -lim), lim)
            W[k, j] = w
            step = v * dt
            half = w * half_dt
            mid = psi + half  # midpoint heading: the exact chord direction of the arc
            px += step * math.cos(mid)
            py += step * math.sin(mid)
            psi += half + half
            sj, ej, h, kap = _project(px, py, sj + step, n_back, n_ahead, x0, y0, tx, ty, chord, s,
                                      s_per_m, heading, kappa, dh, dk, inv_ds)
            th = math.pi - ((math.pi - (psi - h)) % (2.0 * math.pi))  # wrap to (-pi, pi]
            X[k + 1, j], Y[k + 1, j], PSI[k + 1, j], SS[k + 1, j], EE[k + 1, j] = px, py, psi, sj, ej
    return X, Y, PSI, SS, EE, W
