"""The tracker's look-ahead point and speed look-up, compiled with numba.

Every control period :meth:`.tracking.TrajectoryTracker.control` reads the planned speed twice
(``np.interp``) and finds the pure-pursuit target on the planned path (:func:`.tracking.lookahead_point_reference`,
~20 small numpy operations on a 31-point path). These are the same computations as scalar loops, in
numpy's order (``np.interp``'s slope form, ``np.cumsum``'s running sum), so they give the same
floats; the tests hold them to numpy's.

numba is imported here only; :mod:`.tracking` imports this module on its first control call.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def bisect_right(a, value, n):
    """``np.searchsorted(a[:n], value, side="right")``: how many of the sorted ``a[:n]`` are <= ``value``."""
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) >> 1
        if a[mid] <= value:
            lo = mid + 1
        else:
            hi = mid
    return lo

__all__ = ["interp", "lookahead_point"]


@njit(cache=True, nogil=True)
def interp(x, xp, fp):
    """``np.interp(x, xp, fp)`` for a float ``x`` and increasing ``xp`` (N,), ``N >= 2``."""
    n = len(xp)
    if math.isnan(x):
        return x
    if x > xp[n - 1]:
        return fp[n - 1]
    if x < xp[0]:
        return fp[0]
    j = bisect_right(xp, x, n) - 1  # the last index with xp[j] <= x
    if j == n - 1 or xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    y = slope * (x - xp[j]) + fp[j]
    if math.isnan(y):
        y = slope * (x - xp[j + 1]) + fp[j + 1]
        if math.isnan(y) and fp[j] == fp[j + 1]:
            y = fp[j]
    return y


@njit(cache=True, nogil=True)
def lookahead_point(path, px, py, dist):
    """Point ``(x, y)`` [m] ``dist`` [m] along the polyline ``path[:, :2]`` (T, >= 2) from its point
    closest to ``(px, py)`` [m]; past the end along the last segment (see
    :func:`.tracking.lookahead_point_reference`). Segments shorter than 1e-6 m are skipped; with none left,
    the first point."""
    T = path.shape[0]
    sx = np.empty(T - 1)
    sy = np.empty(T - 1)
    gx = np.empty(T - 1)
    gy = np.empty(T - 1)
    L = np.empty(T - 1)
    m = 0
    for i in range(T - 1):
        dx = path[i + 1, 0] - path[i, 0]
        dy = path[i + 1, 1] - path[i, 1]
        length = math.hypot(dx, dy)
        if length > 1e-6:
            sx[m], sy[m], gx[m], gy[m], L[m] = path[i, 0], path[i, 1], dx, dy, length
            m += 1
    if m == 0:
        return path[0, 0], path[0, 1]
    best = np.inf
    j = 0
    tj = 0.0
    for i in range(m):
        dot = 0.0  # numpy's row sum of two products
        dot += (px - sx[i]) * gx[i]
        dot += (py - sy[i]) * gy[i]
        t = dot / (L[i] * L[i])
        t = t if t > 0.0 else 0.0
        t = t if t < 1.0 else 1.0
        d = math.hypot(sx[i] + t * gx[i] - px, sy[i] + t * gy[i] - py)
        if d < best:  # the first minimum, as argmin
            best, j, tj = d, i, t
    cum = np.empty(m + 1)
    cum[0] = 0.0
    cum[1] = L[0]
    for i in range(1, m):
        cum[i + 1] = cum[i] + L[i]
    s_target = cum[j] + tj * L[j] + dist
    if s_target >= cum[m]:
        f = 1.0 + (s_target - cum[m]) / L[m - 1]
        return sx[m - 1] + gx[m - 1] * f, sy[m - 1] + gy[m - 1] * f
    k = bisect_right(cum, s_target, m + 1) - 1  # the last index with cum[k] <= s_target
    f = (s_target - cum[k]) / L[k]
    return sx[k] + gx[k] * f, sy[k] + gy[k] * f
