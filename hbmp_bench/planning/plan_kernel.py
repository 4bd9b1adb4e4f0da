"""One planning call's sampling, roll-out, obstacle cost and collision check, compiled with numba.

After :mod:`.rollout` and :mod:`.obstacle_kernels` were compiled, a :func:`.planner.plan` call
still spent ~70 % of its time in ~120 small numpy operations around them: projecting the ego,
the curve speed cap, building the samples, their speed profiles, limits and gains, resampling the
local reference and building its segments. :func:`plan_samples` runs all of that as scalar loops
and calls the compiled roll-out and obstacle kernels from compiled code, in one call.

It is :func:`.planner.plan_reference` (the numpy form) operation for operation, in the same
order, so the results are the same bits, not only close: the ego's projection is
:meth:`.frame.Path.project`'s (``window = (10, 40)`` m around the hint), the curve cap
:func:`.planner.curve_speed_cap`'s, the local reference :meth:`.frame.Path.resample`'s and
:meth:`.frame.Path.uniform_segments`'s; ``np.arange``, ``np.linspace``, ``np.sinc`` and
``np.mean`` (pairwise summation) are written out as numpy computes them. The tests hold the two
forms to equal arrays. What stays in numpy in :func:`.planner.plan` is what a scalar loop cannot
reproduce bit for bit: ``c_velocity`` (a BLAS matrix-vector product) and ``c_dist`` (numpy's
pairwise row sums), then the choice.

Like the other kernels it is numpy-only code (``NUMBA_DISABLE_JIT=1`` runs it as Python).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .obstacle_kernels import first_contacts, followers, obstacle_cost, project_poses
from .rollout import roll_out
from .tracking_kernel import bisect_right

__all__ = ["plan_samples", "project_pose", "segment_of", "pairwise_sum"]

#: ``np.finfo(float).eps``: ``np.sinc`` evaluates ``sin(y) / y`` at this ``y`` when ``y == 0``.
_EPS = 2.220446049250313e-16
#: Window of the ego's projection around ``s_hint`` [m] (the default of :meth:`.frame.Path.project`).
_BACK, _AHEAD = 10.0, 40.0


@njit(cache=True, nogil=True)
def _wrap(a):
    """``np.pi - np.mod(np.pi - a, 2 pi)`` (:func:`.frame.wrap_angle`)."""
    return math.pi - ((math.pi - a) % (2.0 * math.pi))


@njit(cache=True, nogil=True)
def _clip(a, lo, hi):
    """``np.clip`` of a float (numpy's ``min(max(a, lo), hi)``)."""
    a = a if a > lo else lo
    return a if a < hi else hi


@njit(cache=True, nogil=True)
def segment_of(s, value):
    """``clip(np.searchsorted(s, value, side="right") - 1, 0, len(s) - 2)``: the segment holding ``value``."""
    return min(max(bisect_right(s, value, len(s)) - 1, 0), len(s) - 2)


@njit(cache=True, nogil=True)
def _block_sum(a, lo, n):
    """numpy's pairwise summation of ``a[lo:lo + n]``, ``n <= 128``: 8 partial sums (sequential below 8)."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - n % 8:
        j = lo + i
        r0 += a[j]; r1 += a[j + 1]; r2 += a[j + 2]; r3 += a[j + 3]
        r4 += a[j + 4]; r5 += a[j + 5]; r6 += a[j + 6]; r7 += a[j + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True, nogil=True)
def pairwise_sum(a, lo, n):
    """``np.add.reduce(a[lo:lo + n])`` of float64: numpy's pairwise summation (blocks of up to 128 summed by
    :func:`_block_sum`; longer runs split in halves, cut to a multiple of 8, and the halves' sums added).

    The halving runs on an explicit stack (numba's on-disk cache does not keep recursive functions)."""
    if n <= 128:
        return _block_sum(a, lo, n)
    t_lo = np.empty(192, np.int64)
    t_n = np.empty(192, np.int64)  # -1: add the two sums on top of the value stack
    vals = np.empty(64)
    t_lo[0], t_n[0] = lo, n
    sp, vp = 1, 0
    while sp:
        sp -= 1
        m = t_n[sp]
        if m < 0:
            vals[vp - 2] = vals[vp - 2] + vals[vp - 1]
            vp -= 1
        elif m <= 128:
            vals[vp] = _block_sum(a, t_lo[sp], m)
            vp += 1
        else:
            l0 = t_lo[sp]
            n2 = m // 2
            n2 -= n2 % 8
            t_n[sp] = -1  # after both halves
            t_lo[sp + 1], t_n[sp + 1] = l0 + n2, m - n2  # the second half, summed after
            t_lo[sp + 2], t_n[sp + 2] = l0, n2  # the first half, summed first
            sp += 3
    return vals[0]


@njit(cache=True, nogil=True)
def project_pose(px, py, yaw, hint, ps, x0, y0, tx, ty, chord, heading, kappa, dh, dk):
    """:meth:`.frame.Path.project` of one pose [m, m, rad] with its default window: ``(s, e, theta_e,
    kappa)``; ``hint`` [m], NaN = none; the path as :meth:`.frame.Path.segment_arrays`."""
    nseg = len(chord)
    if math.isnan(hint):
        i0, i1 = 0, nseg - 1
    else:
        i0, i1 = segment_of(ps, hint - _BACK), segment_of(ps, hint + _AHEAD)
    best_d2 = np.inf
    bi = i0
    b_along = b_c = b_cross = 0.0
    for i in range(i0, i1 + 1):
        dx = px - x0[i]
        dy = py - y0[i]
        along = dx * tx[i] + dy * ty[i]
        cross = tx[i] * dy - ty[i] * dx
        c = _clip(along, 0.0, chord[i])
        d = along - c
        d2 = d * d + cross * cross
        if d2 < best_d2:  # the first minimum, as argmin
            best_d2, bi, b_along, b_c, b_cross = d2, i, along, c, cross
    lo = -np.inf if bi == 0 else 0.0
    hi = np.inf if bi == nseg - 1 else chord[bi]
    c_rep = _clip(b_along, lo, hi)
    e = b_cross if c_rep != b_c else math.copysign(math.sqrt(best_d2), b_cross)
    frac = _clip(c_rep / chord[bi], 0.0, 1.0)
    h = _wrap(heading[bi] + frac * dh[bi])
    return ps[bi] + c_rep, e, _wrap(yaw - h), kappa[bi] + frac * dk[bi]


@njit(cache=True, nogil=True)
def _curve_speed_cap(s0, v, ps, chord, kappa, dk, horizon, decel, ds, curve_lat_accel, yaw_rate_max):
    """:func:`.planner.curve_speed_cap` [m/s] (``inf``: no curve ahead)."""
    if not math.isfinite(curve_lat_accel):
        return np.inf
    preview = max(v, 1.0) * horizon + v * v / (2.0 * decel) + 5.0
    start = s0 - 2.0
    n = int(math.ceil((s0 + preview - start) / ds))
    delta = (start + ds) - start  # np.arange fills start + i * delta
    two_decel = 2.0 * decel
    cap = np.inf
    for j in range(max(n, 0)):
        s = start + j * delta if j != 1 else start + ds
        i = segment_of(ps, s)
        c = s - ps[i]
        k = abs(kappa[i] + _clip(c / chord[i], 0.0, 1.0) * dk[i])
        if k > 1e-4:
            v_curve = min(math.sqrt(curve_lat_accel / k), yaw_rate_max / k)
            reach = s - s0
            reach = reach if reach > 0.0 else 0.0
            cap = min(cap, math.sqrt(v_curve * v_curve + two_decel * reach))
    return cap


@njit(cache=True, nogil=True)
def plan_samples(x, y, yaw, v, s_hint, v_ref, speed_limit,
                 ps, x0, y0, tx, ty, chord, heading, kappa, dh, dk,
                 ox, oy, oyaw, ov, olength, owidth,
                 times, dv, dw, dec, p):
    """Samples, roll-outs, ``c_obs`` and collisions of one planning call (see :mod:`.planner`).

    Args:
        x, y, yaw, v: ego pose and speed [m, m, rad, m/s]; ``s_hint``: its previous arc length [m]
            (NaN: none); ``v_ref``, ``speed_limit``: the problem's [m/s].
        ps, x0 ... dk: the reference path: vertex arc length, heading, curvature (N,) and segment
            start, unit tangent, chord, heading and curvature change (N - 1,) [m, rad, 1/m].
        ox ... owidth: (K,) obstacles (:class:`.state.Obstacles` fields).
        times, dv, dw, dec: the config's layout (:func:`.planner._layout`).
        p: (24,) the config's scalars (:func:`.planner.kernel_params`).

    Returns:
        ``(trajectories (S, T, 4), omega (S, T - 1), frenet (S, T, 2), V (S, T), c_obs (S,),
        first (S,), dev (S,), v_ref)`` as :class:`.planner.PlanResult` names them; ``first``: the step
        (index into ``times[1:]``) at which the sample first meets an obstacle, ``T - 1`` where it meets none
        (the ego's followers left out with ``PlannerConfig.ignore_followers``);
        ``dev``: its tie-breaking distance from the nominal sample; ``v_ref``: capped for curves.
    """
    (dt, n_v, n_omega, hold, horizon, accel, decel, yaw_rate_max, max_curvature, lat_accel_max, k_theta, k_e,
     gain_speed, kappa_obs, sigma_obs, length, width, safety_margin, ds, curve_lat_accel, dev_w, dev_v,
     cutoff, ignore_followers) = (p[0], int(p[1]), int(p[2]), int(p[3]), p[4], p[5], p[6], p[7], p[8], p[9], p[10],
                                  p[11], p[12], p[13], p[14], p[15], p[16], p[17], p[18], p[19], p[20], p[21], p[22],
                                  p[23] != 0.0)
    T = len(times)
    n = T - 1
    lat_finite = math.isfinite(lat_accel_max)

    s0, e0, th0, k0 = project_pose(x, y, yaw, s_hint, ps, x0, y0, tx, ty, chord, heading, kappa, dh, dk)
    cap = _curve_speed_cap(s0, v, ps, chord, kappa, dk, horizon, decel, ds, curve_lat_accel, yaw_rate_max)
    v_ref = cap if cap < v_ref else v_ref

    # ---- samples of v(0), omega(0) and the two braking samples
    v_hi = speed_limit if speed_limit > v else v
    av = abs(v)
    lim0 = min(yaw_rate_max, max_curvature * av)
    if lat_finite:
        lim0 = min(lim0, lat_accel_max / (av if av > 1e-6 else 1e-6))
    g0 = min(1.0, gain_speed / max(av, 1e-9))
    kth0 = k_theta * g0
    ke0 = k_e * g0 * g0
    denom = max(1.0 - k0 * e0, 0.1)
    ysinc = math.pi * (th0 / math.pi)
    if ysinc == 0.0:
        ysinc = _EPS
    w_nom = _clip(v * k0 * math.cos(th0) / denom - (kth0 * av) * th0 - (ke0 * v * (math.sin(ysinc) / ysinc)) * e0,
                  -lim0, lim0)
    n_grid = n_v * n_omega
    S = n_grid + 2
    V0 = np.empty(S)
    W0 = np.empty(S)
    v_tgt = np.empty(S)
    for a in range(n_v):
        v0a = _clip(v + dv[a], 0.0, v_hi)
        for b in range(n_omega):
            V0[a * n_omega + b] = v0a
            W0[a * n_omega + b] = w_nom + dw[b]
            v_tgt[a * n_omega + b] = v_ref
    V0[n_grid] = V0[n_grid + 1] = v
    W0[n_grid] = W0[n_grid + 1] = w_nom
    v_tgt[n_grid] = v_tgt[n_grid + 1] = 0.0
    dev = np.empty(S)
    w_off = np.empty(S)
    for j in range(S):
        dev[j] = abs(W0[j] - w_nom) / dev_w + abs(V0[j] - v) / dev_v
        w_off[j] = W0[j] - w_nom
    dev[n_grid] = 1e6  # braking samples: only when strictly cheapest
    dev[n_grid + 1] = 2e6

    # ---- speed profiles, omega limits and scheduled gains; (S, T) speeds, the rest time-major
    V = np.empty((S, T))
    Vt = np.empty((T, S))
    LIM = np.empty((T, S))
    KTH = np.empty((T, S))
    KE = np.empty((T, S))
    vmax = -np.inf
    for j in range(S):
        dvj = v_tgt[j] - V0[j]
        ndec = -dec[j]
        for t in range(T):
            vjt = V0[j] + _clip(dvj, ndec * times[t], accel * times[t])
            V[j, t] = vjt
            Vt[t, j] = vjt
            vmax = max(vmax, vjt)
            a_v = abs(vjt)
            lim = min(yaw_rate_max, max_curvature * a_v)
            if lat_finite:
                lim = min(lim, lat_accel_max / (a_v if a_v > 1e-6 else 1e-6))
            LIM[t, j] = lim
            gsc = min(1.0, gain_speed / (a_v if a_v > 1e-9 else 1e-9))
            KTH[t, j] = k_theta * gsc
            KE[t, j] = k_e * gsc * gsc

    # ---- local reference resampled every ds metres (Path.resample + Path.uniform_segments)
    a0 = s0 - 10.0 - 2 * ds
    b0 = s0 + vmax * horizon + 20.0
    if not b0 - a0 > 0:
        raise ValueError("empty resampling window")
    m = max(int(math.ceil((b0 - a0) / ds)), 1)
    step = (b0 - a0) / m
    ls = np.empty(m + 1)
    lx = np.empty(m + 1)
    ly = np.empty(m + 1)
    lh = np.empty(m + 1)
    lk = np.empty(m + 1)
    for q in range(m + 1):
        sq = q * step + a0 if q < m else b0
        i = segment_of(ps, sq)
        c = sq - ps[i]
        frac = _clip(c / chord[i], 0.0, 1.0)
        ls[q] = sq
        lx[q] = x0[i] + c * tx[i]
        ly[q] = y0[i] + c * ty[i]
        lh[q] = _wrap(heading[i] + frac * dh[i])
        lk[q] = kappa[i] + frac * dk[i]
    ds_step = np.empty(m)
    for q in range(m):
        ds_step[q] = ls[q + 1] - ls[q]
    inv_ds = 1.0 / (pairwise_sum(ds_step, 0, m) / m)
    u_x0 = lx[:m].copy()
    u_y0 = ly[:m].copy()
    u_tx = np.empty(m)
    u_ty = np.empty(m)
    u_chord = np.empty(m)
    u_s = ls[:m].copy()
    u_spm = np.empty(m)
    u_h = lh[:m].copy()
    u_k = lk[:m].copy()
    u_dh = np.empty(m)
    u_dk = np.empty(m)
    for q in range(m):
        ddx = lx[q + 1] - lx[q]
        ddy = ly[q + 1] - ly[q]
        chord_q = max(math.hypot(ddx, ddy), 1e-12)
        u_chord[q] = chord_q
        u_tx[q] = ddx / chord_q
        u_ty[q] = ddy / chord_q
        u_spm[q] = ds_step[q] / chord_q
        u_dh[q] = _wrap(lh[q + 1] - lh[q])
        u_dk[q] = lk[q + 1] - lk[q]

    # ---- roll-out (time-major), obstacle cost and collisions
    X, Y, PSI, SS, EE, W = roll_out(x, y, yaw, s0, e0, th0, k0, Vt, KTH, KE, LIM, w_off, hold, dt, 2, 2,
                                    u_x0, u_y0, u_tx, u_ty, u_chord, u_s, u_spm, u_h, u_k, u_dh, u_dk, inv_ds)
    future = times[1:].copy()
    so0, eo0, tho = project_poses(ox, oy, oyaw, u_x0, u_y0, u_tx, u_ty, u_chord, u_s, u_h, u_dh)
    c_obs = obstacle_cost(SS[1:].copy(), EE[1:].copy(), so0, eo0, tho, ov, olength, owidth, future, length,
                          width, kappa_obs, sigma_obs, cutoff)
    checked = (~followers(so0, eo0, tho, olength, owidth, s0, e0, length, width) if ignore_followers
               else np.ones(len(ox), np.bool_))
    first = first_contacts(X[1:].copy(), Y[1:].copy(), PSI[1:].copy(), ox[checked], oy[checked], oyaw[checked],
                           ov[checked], olength[checked], owidth[checked], future,
                           0.5 * length + safety_margin, 0.5 * width + safety_margin)

    traj = np.empty((S, T, 4))
    frenet = np.empty((S, T, 2))
    omega = np.empty((S, n))
    for j in range(S):
        for t in range(T):
            traj[j, t, 0] = X[t, j]
            traj[j, t, 1] = Y[t, j]
            traj[j, t, 2] = PSI[t, j]
            traj[j, t, 3] = V[j, t]
            frenet[j, t, 0] = SS[t, j]
            frenet[j, t, 1] = EE[t, j]
        for t in range(n):
            omega[j, t] = W[t, j]
    return traj, omega, frenet, V, c_obs, first, dev, v_ref
