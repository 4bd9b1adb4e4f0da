"""The detectors' lane lookup compiled with numba: :meth:`.geometry.LaneLocator.locate` for one footprint.

Every sim step the infraction detector asks which lane lies under 15 footprint points of the ego.
Its numpy form (:meth:`.geometry.LaneLocator.locate_reference`) is ~30 small array operations on
(15, M) arrays of the M candidate segments, plus an even-odd test per nearby junction polygon;
their per-call overhead, not the arithmetic, was ~0.2 ms a step (about one raw SUMO step).
:func:`locate_points` runs the same arithmetic as scalar loops, in the same order, so it gives the
same lanes, directions and junction flags (the tests hold the two forms to equal arrays).
:func:`locate_footprints` does it for the footprints of every vehicle of a step in one call, the grid
query included (the world's batched detectors, :func:`.detectors.update_all`): per call the same
candidates and arithmetic, so the same results as one :func:`locate_points` per vehicle.

numba is imported here only; :meth:`.geometry.LaneLocator.locate` imports this module on first use.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["locate_footprints", "locate_points"]


@njit(cache=True, nogil=True)
def locate_points(points, candidates, bounds, a, unit, seg_len, half_width, lane_index, seg_edge, prefer,
                  junction_lo, junction_hi, junction_xy, junction_start):
    """Lane, lane direction and junction flag of P points.

    Args:
        points: (P, 2) [m].
        candidates: ascending segment indices the grid gives for the points' box.
        bounds: (M, 4) ``[hi_x, hi_y, -lo_x, -lo_y]`` of each segment's box [m].
        a, unit, seg_len, half_width, lane_index: (M, 2) segment start [m], (M, 2) unit direction,
            (M,) length [m], (M,) lane half width [m], (M,) lane of each segment (negative: a junction
            lane, whose surface counts as junction where no normal lane covers a point).
        seg_edge: (M,) edge number of each segment's lane; ``prefer``: the edge number whose lanes win
            where lanes overlap in plan view (-1: none).
        junction_lo, junction_hi: (J, 2) junction polygon boxes [m]; ``junction_xy`` (sum N_j, 2) their
            vertices, junction ``j`` at rows ``junction_start[j]:junction_start[j + 1]``.

    Returns:
        ``(lane (P,) int (-1: none), direction (P, 2), in_junction (P,) bool)``: in a junction polygon, or
        on a junction lane and on no normal lane.
    """
    P = points.shape[0]
    lane = np.full(P, -1, np.int64)
    direction = np.zeros((P, 2))
    in_junction = np.zeros(P, np.bool_)
    _locate_into(points, candidates, bounds, a, unit, seg_len, half_width, lane_index, seg_edge, prefer, junction_lo,
                 junction_hi, junction_xy, junction_start, lane, direction, in_junction)
    return lane, direction, in_junction


@njit(cache=True, nogil=True)
def _locate_into(points, candidates, bounds, a, unit, seg_len, half_width, lane_index, seg_edge, prefer,
                 junction_lo, junction_hi, junction_xy, junction_start, lane, direction, in_junction):
    """:func:`locate_points` writing into ``lane``, ``direction`` and ``in_junction`` (P rows each, as
    initialised there)."""
    P = points.shape[0]
    lo_x = hi_x = points[0, 0]
    lo_y = hi_y = points[0, 1]
    for p in range(1, P):
        lo_x = min(lo_x, points[p, 0])
        hi_x = max(hi_x, points[p, 0])
        lo_y = min(lo_y, points[p, 1])
        hi_y = max(hi_y, points[p, 1])
    near = np.empty(len(candidates), np.int64)
    m = 0
    for c in candidates:
        if bounds[c, 0] >= lo_x and bounds[c, 1] >= lo_y and bounds[c, 2] >= -hi_x and bounds[c, 3] >= -hi_y:
            near[m] = c
            m += 1
    for p in range(P):
        px = points[p, 0]
        py = points[p, 1]
        best = own_best = np.inf
        best_c = own_c = -1
        junction_lane = False
        for q in range(m):
            c = near[q]
            ux = unit[c, 0]
            uy = unit[c, 1]
            t = (px - a[c, 0]) * ux + (py - a[c, 1]) * uy
            t = t if t >= 0.0 else 0.0
            t = t if t <= seg_len[c] else seg_len[c]
            d = math.hypot(px - (a[c, 0] + t * ux), py - (a[c, 1] + t * uy))
            if d <= half_width[c]:
                if lane_index[c] < 0:  # a junction lane: junction surface, not a lane to judge against
                    junction_lane = True
                    continue
                if d < best:  # the first minimum, as argmin
                    best, best_c = d, c
                if seg_edge[c] == prefer and d < own_best:
                    own_best, own_c = d, c
        k = own_c if own_c >= 0 else best_c
        if k >= 0:
            lane[p] = lane_index[k]
            direction[p, 0] = unit[k, 0]
            direction[p, 1] = unit[k, 1]
        elif junction_lane:
            in_junction[p] = True
    for j in range(len(junction_lo)):
        if not (junction_hi[j, 0] >= lo_x and junction_hi[j, 1] >= lo_y
                and junction_lo[j, 0] <= hi_x and junction_lo[j, 1] <= hi_y):
            continue
        j0 = junction_start[j]
        n = junction_start[j + 1] - j0
        for p in range(P):
            x = points[p, 0]
            y = points[p, 1]
            inside = False
            for i in range(n):
                ax = junction_xy[j0 + i, 0]
                ay = junction_xy[j0 + i, 1]
                b = j0 + (i + 1) % n
                bx = junction_xy[b, 0]
                by = junction_xy[b, 1]
                if (ay > y) != (by > y) and x < ax + (y - ay) * (bx - ax) / (by - ay):
                    inside = not inside
            if inside:
                in_junction[p] = True



@njit(cache=True, nogil=True)
def _grid_candidates(points, origin, cell, nx, ny, items, starts):
    """:meth:`.geometry.SegmentGrid.query` for the box of ``points`` (P, 2): the same indices, ascending."""
    lo_x = hi_x = points[0, 0]
    lo_y = hi_y = points[0, 1]
    for p in range(1, points.shape[0]):
        lo_x = min(lo_x, points[p, 0])
        hi_x = max(hi_x, points[p, 0])
        lo_y = min(lo_y, points[p, 1])
        hi_y = max(hi_y, points[p, 1])
    x0 = max(math.floor((lo_x - origin[0]) / cell), 0)
    y0 = max(math.floor((lo_y - origin[1]) / cell), 0)
    x1 = min(math.floor((hi_x - origin[0]) / cell), nx - 1)
    y1 = min(math.floor((hi_y - origin[1]) / cell), ny - 1)
    if x1 < x0 or y1 < y0:
        return items[:0]
    if x0 == x1 and y0 == y1:
        return items[starts[x0 * ny + y0]:starts[x0 * ny + y0 + 1]]
    count = 0
    for cx in range(x0, x1 + 1):
        count += starts[cx * ny + y1 + 1] - starts[cx * ny + y0]
    out = np.empty(count, items.dtype)
    m = 0
    for cx in range(x0, x1 + 1):
        for i in range(starts[cx * ny + y0], starts[cx * ny + y1 + 1]):
            out[m] = items[i]
            m += 1
    return np.unique(out)


@njit(cache=True, nogil=True)
def locate_footprints(points, prefer, origin, cell, nx, ny, items, starts, bounds, a, unit, seg_len, half_width,
                      lane_index, seg_edge, junction_lo, junction_hi, junction_xy, junction_start):
    """:func:`locate_points` of N footprints in one call, each with its own grid query and preferred edge.

    Args:
        points: (N, P, 2) [m], footprint ``n`` at ``points[n]``.
        prefer: (N,) the preferred edge number of each footprint (-1: none).
        origin, cell, nx, ny, items, starts: the :class:`.geometry.SegmentGrid` of the segments.
        bounds ... junction_start: as :func:`locate_points`.

    Returns:
        ``(lane (N, P), direction (N, P, 2), in_junction (N, P))``, row ``n`` equal to
        :func:`locate_points` of footprint ``n`` with the grid's candidates for its box.
    """
    N, P = points.shape[0], points.shape[1]
    lane = np.full((N, P), -1, np.int64)
    direction = np.zeros((N, P, 2))
    in_junction = np.zeros((N, P), np.bool_)
    for n in range(N):
        candidates = _grid_candidates(points[n], origin, cell, nx, ny, items, starts)
        _locate_into(points[n], candidates, bounds, a, unit, seg_len, half_width, lane_index, seg_edge, prefer[n],
                     junction_lo, junction_hi, junction_xy, junction_start, lane[n], direction[n], in_junction[n])
    return lane, direction, in_junction


def compile_kernel() -> None:
    """Compile :func:`locate_points` and :func:`locate_footprints` (or load them from numba's on-disk cache)
    for the argument types :meth:`.geometry.LaneLocator.locate` and ``locate_all`` pass, so that the first
    lookup of a timed run does not compile."""
    seg = np.array([[0.0, 0.0], [10.0, 0.0]])
    unit = np.array([[1.0, 0.0]])
    bounds = np.array([[10.0, 2.0, 0.0, 2.0]])
    locate_points(np.array([[1.0, 0.5], [2.0, -0.5]]), np.arange(1), bounds, seg[:1].copy(), unit, np.array([10.0]),
                  np.array([1.75]), np.zeros(1, np.int64), np.zeros(1, np.int64), 0, np.zeros((1, 2)),
                  np.ones((1, 2)), seg.copy(), np.array([0, 2], np.int64))
    locate_footprints(np.array([[[1.0, 0.5], [2.0, -0.5]]]), np.zeros(1, np.int64), np.zeros(2), 16.0, 1, 1,
                      np.zeros(1, np.int64), np.array([0, 1], np.int64), bounds, seg[:1].copy(), unit, np.array([10.0]),
                      np.array([1.75]), np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros((1, 2)), np.ones((1, 2)),
                      seg.copy(), np.array([0, 2], np.int64))
