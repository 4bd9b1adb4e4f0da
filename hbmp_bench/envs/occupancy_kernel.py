"""The deformed occupancy grid M_t rasterised in one compiled call (numba).

:func:`.observation.occupancy_grid` samples every nearby footprint at ~40 points, projects the
~3000 points on the followed lane's centreline (a windowed nearest-segment search) and marks the
cells they fall in. Its numpy form (:func:`.observation.occupancy_grid_reference`) builds (points ×
segments) temporaries for the projection, ~0.4 ms a decision (two raw SUMO steps; in the event
fidelity a decision is one sim step). :func:`deformed_grid` runs the same arithmetic per point, in
numpy's order (``np.linspace`` for the sample offsets, :meth:`.planning.frame.Path.frenet`'s nearest
segment and its straight extension past both ends), so it marks the same cells (tested). Per footprint it
first keeps the window's segments that can be a sample's nearest (:func:`_candidate_segments`) and skips a
footprint that can mark no cell (:func:`_marks_nothing`): bounds from the footprint's centre, with a margin far
above float error, so the search finds the same nearest segment (half the time of the full search in dense
Town03, where ~40 actors are within reach of every M_t).

numba is imported here only; :func:`.observation.occupancy_grid` imports this module on first use (and
this module imports nothing of ``envs``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from hbmp_bench.planning.plan_kernel import project_pose, segment_of

__all__ = ["deformed_grid"]


@njit(cache=True, nogil=True)
def _linspace_half(n):
    """``np.linspace(-0.5, 0.5, n)``, ``n >= 2``."""
    out = np.empty(n)
    step = 1.0 / (n - 1)
    for i in range(n - 1):
        out[i] = i * step + -0.5
    out[n - 1] = 0.5
    return out



PRUNE_MARGIN_M = 1e-6
"""Slack of the pruning bounds of :func:`_candidate_segments` and :func:`_marks_nothing` [m]: far above the
float error of the distances (~1e-10 m on a town's coordinates), far below a cell."""


@njit(cache=True, nogil=True)
def _segment_distance(px, py, i, x0, y0, tx, ty, chord):
    """Distance [m] from (px, py) to segment ``i`` of the centreline (clamped to its ends)."""
    dx = px - x0[i]
    dy = py - y0[i]
    along = dx * tx[i] + dy * ty[i]
    cross = tx[i] * dy - ty[i] * dx
    cc = along if along > 0.0 else 0.0
    cc = cc if cc < chord[i] else chord[i]
    return math.hypot(along - cc, cross)


@njit(cache=True, nogil=True)
def _candidate_segments(cx, cy, radius, i0, i1, x0, y0, tx, ty, chord, kept):
    """The segments of the window ``i0..i1`` that can be the nearest one of a point within ``radius`` [m]
    of (cx, cy) (a footprint's samples around its centre), ascending into ``kept``; returns their count.

    A point p with ``|p - c| <= radius`` is within ``D_min + radius`` of its nearest segment and at least
    ``D_i - radius`` from segment ``i`` (``D``: distances from c; a distance to a segment is 1-Lipschitz),
    so a segment with ``D_i > D_min + 2 radius`` (plus :data:`PRUNE_MARGIN_M`) is never its nearest: the
    search over the rest finds the same first minimum."""
    d_min = np.inf
    for i in range(i0, i1 + 1):
        d_min = min(d_min, _segment_distance(cx, cy, i, x0, y0, tx, ty, chord))
    limit = d_min + 2.0 * radius + PRUNE_MARGIN_M
    m = 0
    for i in range(i0, i1 + 1):
        if _segment_distance(cx, cy, i, x0, y0, tx, ty, chord) <= limit:
            kept[m] = i
            m += 1
    return m


@njit(cache=True, nogil=True)
def _marks_nothing(kept, m, nseg, cx, cy, radius, x0, y0, tx, ty, chord, ps, s_ego, rows, cell_long, back_m,
                   half_width):
    """True when no sample within ``radius`` [m] of (cx, cy) can mark a cell: every candidate segment is an
    inner one (neither end of the centreline, whose straight extension projects past it), and either all
    their rows lie outside the grid (the row is monotone in the position along a segment) or every sample
    is farther than ``half_width`` from them (on an inner segment ``|e|`` is the distance)."""
    for q in range(m):
        if kept[q] == 0 or kept[q] == nseg - 1:
            return False
    inside_rows = False
    for q in range(m):
        i = kept[q]
        first = math.floor((ps[i] + 0.0 - s_ego + back_m) / cell_long)
        last = math.floor((ps[i] + chord[i] - s_ego + back_m) / cell_long)
        if last >= 0 and first < rows:
            inside_rows = True
    if not inside_rows:
        return True
    d_min = np.inf
    for q in range(m):
        d_min = min(d_min, _segment_distance(cx, cy, kept[q], x0, y0, tx, ty, chord))
    return d_min - radius > half_width + PRUNE_MARGIN_M

@njit(cache=True, nogil=True)
def deformed_grid(ego_x, ego_y, xs, ys, yaws, lengths, widths, n_long, n_lat, ps, x0, y0, tx, ty, chord, heading,
                  kappa, dh, dk, rows, cols, cell_long, cell_lat, back_m, ahead_m, half_width):
    """M_t (1, rows, cols) float32 of K footprints in the followed lane's curvilinear frame.

    Args:
        ego_x, ego_y: the ego centre [m].
        xs, ys, yaws, lengths, widths: (K,) the footprints to mark: centre [m], heading [rad], size [m].
        n_long, n_lat: sample points along / across every footprint (corners included).
        ps ... dk: the followed lane's centreline (:meth:`.planning.frame.Path.segment_arrays`).
        rows, cols, cell_long, cell_lat, back_m, ahead_m, half_width: the grid
            (:class:`.observation.ObservationConfig`) [cells, m].
    """
    grid = np.zeros((1, rows, cols), np.float32)
    _deformed_into(grid, ego_x, ego_y, xs, ys, yaws, lengths, widths, n_long, n_lat, ps, x0, y0, tx, ty, chord, heading,
                   kappa, dh, dk, rows, cols, cell_long, cell_lat, back_m, ahead_m, half_width)
    return grid


@njit(cache=True, nogil=True)
def _deformed_into(grid, ego_x, ego_y, xs, ys, yaws, lengths, widths, n_long, n_lat, ps, x0, y0, tx, ty, chord, heading,
                   kappa, dh, dk, rows, cols, cell_long, cell_lat, back_m, ahead_m, half_width):
    """:func:`deformed_grid` marking the cells in ``grid`` (1, rows, cols), zeros on entry."""
    s_ego = project_pose(ego_x, ego_y, 0.0, np.nan, ps, x0, y0, tx, ty, chord, heading, kappa, dh, dk)[0]
    nseg = len(chord)
    i0 = segment_of(ps, s_ego - (back_m + 10.0))
    i1 = segment_of(ps, s_ego + (ahead_m + 10.0))
    u = _linspace_half(n_long)
    v = _linspace_half(n_lat)
    kept = np.empty(i1 - i0 + 1, np.int64)
    for k in range(len(xs)):
        c = math.cos(yaws[k])
        s = math.sin(yaws[k])
        m = _candidate_segments(xs[k], ys[k], 0.5 * math.hypot(lengths[k], widths[k]), i0, i1, x0, y0, tx, ty, chord,
                                kept)
        if _marks_nothing(kept, m, nseg, xs[k], ys[k], 0.5 * math.hypot(lengths[k], widths[k]), x0, y0, tx, ty, chord,
                          ps, s_ego, rows, cell_long, back_m, half_width):
            continue
        for a in range(n_long):
            lon = u[a] * lengths[k]
            for b in range(n_lat):
                lat = v[b] * widths[k]
                px = xs[k] + c * lon - s * lat
                py = ys[k] + s * lon + c * lat
                best_d2 = np.inf
                bi = i0
                b_along = b_c = b_cross = 0.0
                for q in range(m):  # Path.frenet's windowed nearest segment, among those that can be it
                    i = kept[q]
                    dx = px - x0[i]
                    dy = py - y0[i]
                    along = dx * tx[i] + dy * ty[i]
                    cross = tx[i] * dy - ty[i] * dx
                    cc = along if along > 0.0 else 0.0
                    cc = cc if cc < chord[i] else chord[i]
                    d = along - cc
                    d2 = d * d + cross * cross
                    if d2 < best_d2:
                        best_d2, bi, b_along, b_c, b_cross = d2, i, along, cc, cross
                lo = -np.inf if bi == 0 else 0.0
                hi = np.inf if bi == nseg - 1 else chord[bi]
                c_rep = b_along if b_along > lo else lo
                c_rep = c_rep if c_rep < hi else hi
                e = b_cross if c_rep != b_c else math.copysign(math.sqrt(best_d2), b_cross)
                row = math.floor((ps[bi] + c_rep - s_ego + back_m) / cell_long)
                col = math.floor((e + half_width) / cell_lat)
                if 0 <= row < rows and 0 <= col < cols:
                    grid[0, row, col] = 1.0


@njit(cache=True, nogil=True)
def deformed_grids(ego_xy, actor_start, xs, ys, yaws, lengths, widths, n_long, n_lat, seg_start, ps, x0, y0, tx, ty,
                   chord, heading, kappa, dh, dk, rows, cols, cell_long, cell_lat, back_m, ahead_m, half_width):
    """:func:`deformed_grid` of N vehicles in one call: (N, 1, rows, cols) float32, row ``n`` equal to
    :func:`deformed_grid` of vehicle ``n``'s footprints and centreline.

    Args:
        ego_xy: (N, 2) the vehicles' centres [m].
        actor_start: (N + 1,) vehicle ``n``'s footprints are ``xs[actor_start[n]:actor_start[n + 1]]`` (and
            the same rows of ``ys``, ``yaws``, ``lengths``, ``widths``); ``n_long``, ``n_lat``: (N,) its
            sampling.
        seg_start: (N + 1,) vehicle ``n``'s centreline is segments ``seg_start[n]:seg_start[n + 1]`` of
            ``x0`` ... ``dk`` and vertices ``seg_start[n] + n:seg_start[n + 1] + n + 1`` of ``ps``.
        rows ... half_width: the grid, as :func:`deformed_grid`.
    """
    N = ego_xy.shape[0]
    grids = np.zeros((N, 1, rows, cols), np.float32)
    for n in range(N):
        a0, a1 = actor_start[n], actor_start[n + 1]
        s0, s1 = seg_start[n], seg_start[n + 1]
        _deformed_into(grids[n], ego_xy[n, 0], ego_xy[n, 1], xs[a0:a1], ys[a0:a1], yaws[a0:a1], lengths[a0:a1],
                       widths[a0:a1], n_long[n], n_lat[n], ps[s0 + n:s1 + n + 1], x0[s0:s1], y0[s0:s1], tx[s0:s1],
                       ty[s0:s1], chord[s0:s1], heading[s0 + n:s1 + n + 1], kappa[s0 + n:s1 + n + 1], dh[s0:s1],
                       dk[s0:s1], rows, cols, cell_long, cell_lat, back_m, ahead_m, half_width)
    return grids


def compile_kernel() -> None:
    """Compile :func:`deformed_grid` and :func:`deformed_grids` (or load them from numba's on-disk cache) for
    the argument types :func:`.observation.occupancy_grid` and ``ObservationBuilder.occupancy_all`` pass
    (C-contiguous float64 arrays, Python ints and floats, a :class:`~hbmp_bench.planning.frame.Path`'s segment
    arrays or their concatenation), so that the first M_t of a timed run does not compile. (It calls the
    kernels itself: this module never imports ``observation``.)"""
    from hbmp_bench.planning.frame import Path

    path = Path(np.column_stack([np.linspace(-20.0, 60.0, 9), np.zeros(9)]))
    deformed_grid(0.0, 0.0, np.array([8.0]), np.array([3.5]), np.zeros(1), np.array([4.5]), np.array([1.8]), 10, 4,
                  *path.segment_arrays(), 64, 36, 1.0, 0.5, 16.0, 48.0, 9.0)
    deformed_grids(np.zeros((1, 2)), np.array([0, 1]), np.array([8.0]), np.array([3.5]), np.zeros(1), np.array([4.5]),
                   np.array([1.8]), np.array([10]), np.array([4]), np.array([0, len(path.segment_arrays()[1])]),
                   *(np.array(a) for a in path.segment_arrays()), 64, 36, 1.0, 0.5, 16.0, 48.0, 9.0)
