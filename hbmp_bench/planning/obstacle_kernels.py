"""The planner's obstacle stage compiled with numba: ``c_obs`` and the collision check.

:func:`.planner.plan` scores S = 65 samples over T = 30 steps against K obstacles (7 on
average in town traffic, up to ~20). Its numpy form (:func:`.planner.obstacle_cost_reference`,
:func:`.planner.first_contacts_reference`) spends most of its time in the per-call overhead of
~40 small array operations; these kernels run the same arithmetic as scalar loops.

* :func:`project_poses` -- :meth:`.frame.Path.project` without a hint (nearest segment over the
  whole path, straight extension past both ends), on a path's :class:`.frame.UniformSegments`.
* :func:`obstacle_cost` -- ``c_obs`` with the same formula and the same skipping rule (an
  (obstacle, step) pair is skipped when its exponent exceeds ``cutoff`` for every sample). The
  numpy reference sums in float32, the kernel in float64: they agree to ~1e-6 relative
  (tested to ``5e-6 c_obs + 1e-7``).
* :func:`first_contacts` -- the same broad phases and separating-axis test in float64 as the
  reference: the same first contact step of every sample.

Like :mod:`.rollout`, the code stays numpy-only: with ``NUMBA_DISABLE_JIT=1`` (or ``.py_func``)
it runs as plain Python. numba is imported here and in :mod:`.rollout` only; :func:`.planner.plan`
imports this module when first called.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["project_poses", "obstacle_cost", "first_contacts", "followers"]


@njit(cache=True, nogil=True)
def _wrap(a):
    """Angle wrapped to ``(-pi, pi]`` [rad] (as :func:`.frame.wrap_angle`)."""
    return math.pi - ((math.pi - a) % (2.0 * math.pi))


@njit(cache=True, nogil=True)
def project_poses(px, py, yaw, x0, y0, tx, ty, chord, s, heading, dh):
    """``(s, e, theta_e)`` of K poses on a path, each (K,) [m, m, rad].

    Args:
        px, py, yaw: (K,) positions [m] and headings [rad].
        x0 ... dh: the path's :class:`.frame.UniformSegments` fields of those names.

    The nearest segment by true distance over all segments (the first of equals); beyond the
    first and last segment the path extends straight and ``e`` is the perpendicular offset from
    the extension (as :meth:`.frame.Path.project` with ``hint_s=None``).
    """
    K = len(px)
    n = len(chord)
    out_s = np.empty(K)
    out_e = np.empty(K)
    out_th = np.empty(K)
    for k in range(K):
        best_d2 = np.inf
        bi = 0
        b_along = 0.0
        b_c = 0.0
        b_cross = 0.0
        for i in range(n):
            dx = px[k] - x0[i]
            dy = py[k] - y0[i]
            along = dx * tx[i] + dy * ty[i]
            cross = tx[i] * dy - ty[i] * dx
            c = min(max(along, 0.0), chord[i])
            d = along - c
            d2 = d * d + cross * cross
            if d2 < best_d2:
                best_d2, bi, b_along, b_c, b_cross = d2, i, along, c, cross
        lo = -np.inf if bi == 0 else 0.0
        hi = np.inf if bi == n - 1 else chord[bi]
        c_rep = min(max(b_along, lo), hi)
        out_e[k] = b_cross if c_rep != b_c else math.copysign(math.sqrt(best_d2), b_cross)
        out_s[k] = s[bi] + c_rep
        frac = min(max(c_rep / chord[bi], 0.0), 1.0)
        out_th[k] = _wrap(yaw[k] - _wrap(heading[bi] + frac * dh[bi]))
    return out_s, out_e, out_th


@njit(cache=True, nogil=True)
def obstacle_cost(SS, EE, so0, eo0, tho, ov, olength, owidth, times, length, width, kappa_obs, sigma_obs,
                  cutoff):
    """(S,) ``c_obs`` of S samples (see :mod:`.planner`).

    Args:
        SS, EE: (T, S) sample arc length and lateral offset [m] at ``times`` (T,) [s].
        so0, eo0, tho: (K,) obstacles' arc length, lateral offset [m] and heading error [rad]
            on the reference at t = 0; ``ov`` (K,) speed [m/s]; ``olength, owidth`` (K,) [m].
        length, width: ego footprint [m]; ``kappa_obs``, ``sigma_obs`` [m]: the cost's weights.
        cutoff: (obstacle, step) pairs whose exponent exceeds this for every sample are skipped.
    """
    T, S = SS.shape
    acc = np.zeros(S)
    if len(so0) == 0:
        return acc
    s_lo = np.empty(T)
    s_hi = np.empty(T)
    e_lo = np.empty(T)
    e_hi = np.empty(T)
    for t in range(T):
        s_lo[t] = s_hi[t] = SS[t, 0]
        e_lo[t] = e_hi[t] = EE[t, 0]
        for j in range(1, S):
            s_lo[t] = min(s_lo[t], SS[t, j])
            s_hi[t] = max(s_hi[t], SS[t, j])
            e_lo[t] = min(e_lo[t], EE[t, j])
            e_hi[t] = max(e_hi[t], EE[t, j])
    neg_inv_sigma = -1.0 / sigma_obs
    limit = cutoff * sigma_obs
    for k in range(len(so0)):
        vs = ov[k] * math.cos(tho[k])
        ve = ov[k] * math.sin(tho[k])
        half_l = 0.5 * (length + olength[k])
        half_w = 0.5 * (width + owidth[k])
        for t in range(T):
            so = so0[k] + vs * times[t]
            eo = eo0[k] + ve * times[t]
            glon = max(max(so - s_hi[t], s_lo[t] - so) - half_l, 0.0)
            glat = max(max(eo - e_hi[t], e_lo[t] - eo) - half_w, 0.0)
            if not glon + kappa_obs * glat < limit:
                continue
            for j in range(S):
                g = (max(abs(SS[t, j] - so) - half_l, 0.0)
                     + kappa_obs * max(abs(EE[t, j] - eo) - half_w, 0.0))
                acc[j] += math.exp(g * neg_inv_sigma)
    return acc / T


@njit(cache=True, nogil=True)
def followers(so, eo, theta, olength, owidth, s0, e0, length, width):
    """(K,) True for the obstacles that follow the ego: wholly behind it along the path, in its line (their
    footprints overlap sideways) and heading the path's way (within 45 degrees).

    Args:
        so, eo, theta: (K,) obstacles' arc length, lateral offset [m] and heading to the path [rad] (as
            :func:`project_poses`); olength, owidth: (K,) their footprints [m].
        s0, e0: the ego's arc length and offset on the same path [m]; length, width: its footprint [m].
    """
    K = len(so)
    out = np.empty(K, np.bool_)
    for k in range(K):
        out[k] = (so[k] + 0.5 * olength[k] < s0 - 0.5 * length and abs(eo[k] - e0) < 0.5 * (width + owidth[k])
                  and abs(theta[k]) < 0.25 * math.pi)
    return out


@njit(cache=True, nogil=True)
def first_contacts(X, Y, PSI, ox, oy, oyaw, ov, olength, owidth, times, half_length, half_width):
    """(S,) int64: the first step (index into ``times``) at which a sample's footprint meets an obstacle;
    ``T`` where it meets none (the sample is collision-free).

    Args:
        X, Y, PSI: (T, S) ego footprint centres [m] and headings [rad] at ``times`` (T,) [s].
        ox, oy, oyaw, ov, olength, owidth: (K,) obstacles now: centre [m], heading [rad], speed
            along it [m/s], footprint [m]; predicted at constant velocity.
        half_length, half_width: the ego's inflated half footprint [m].

    Broad phases (bounding circles against the step's box of all samples, then against each
    sample), then the exact separating-axis test of the two oriented rectangles.
    """
    T, S = X.shape
    first = np.full(S, T, dtype=np.int64)
    if len(ox) == 0:
        return first
    x_lo = np.empty(T)
    x_hi = np.empty(T)
    y_lo = np.empty(T)
    y_hi = np.empty(T)
    for t in range(T):
        x_lo[t] = x_hi[t] = X[t, 0]
        y_lo[t] = y_hi[t] = Y[t, 0]
        for j in range(1, S):
            x_lo[t] = min(x_lo[t], X[t, j])
            x_hi[t] = max(x_hi[t], X[t, j])
            y_lo[t] = min(y_lo[t], Y[t, j])
            y_hi[t] = max(y_hi[t], Y[t, j])
    r_e = math.hypot(half_length, half_width)
    for k in range(len(ox)):
        co = math.cos(oyaw[k])
        so = math.sin(oyaw[k])
        vx = ov[k] * co
        vy = ov[k] * so
        hl_o = 0.5 * olength[k]
        hw_o = 0.5 * owidth[k]
        reach = r_e + 0.5 * math.hypot(olength[k], owidth[k])
        for t in range(T):
            cx = ox[k] + vx * times[t]
            cy = oy[k] + vy * times[t]
            if cx + reach < x_lo[t] or cx - reach > x_hi[t] or cy + reach < y_lo[t] or cy - reach > y_hi[t]:
                continue
            for j in range(S):
                if first[j] <= t:  # an earlier contact (this obstacle's steps come in order)
                    continue
                dx = cx - X[t, j]
                dy = cy - Y[t, j]
                if dx * dx + dy * dy > reach * reach:
                    continue
                ce = math.cos(PSI[t, j])
                se = math.sin(PSI[t, j])
                cd = abs(ce * co + se * so)
                sd = abs(se * co - ce * so)
                if abs(dx * ce + dy * se) > half_length + hl_o * cd + hw_o * sd:
                    continue
                if abs(-dx * se + dy * ce) > half_width + hl_o * sd + hw_o * cd:
                    continue
                if abs(dx * co + dy * so) > hl_o + half_length * cd + half_width * sd:
                    continue
                if abs(-dx * so + dy * co) > hw_o + half_length * sd + half_width * cd:
                    continue
                first[j] = t
    return first
