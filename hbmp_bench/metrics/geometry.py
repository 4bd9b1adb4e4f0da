"""Footprint geometry for the detectors: oriented boxes, overlap tests, lane lookup, stop lines. Pure numpy."""

from __future__ import annotations

import functools
import math

import numpy as np

from hbmp_bench.maps.roadnet import RoadNetwork


def box_corners(xy: np.ndarray, yaw: np.ndarray, length: np.ndarray, width: np.ndarray) -> np.ndarray:
    """Corners (K, 4, 2) [m] of K oriented boxes given centres (K, 2), yaw (K,) [rad], sizes (K,) [m]."""
    xy = np.atleast_2d(xy)
    c, s = np.cos(yaw), np.sin(yaw)
    fwd = np.stack([c, s], axis=-1) * (np.asarray(length) / 2)[..., None]
    left = np.stack([-s, c], axis=-1) * (np.asarray(width) / 2)[..., None]
    return np.stack([xy + fwd + left, xy - fwd + left, xy - fwd - left, xy + fwd - left], axis=-2)


def boxes_overlap(box: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Separating-axis test of one box (4, 2), or of K boxes pairwise (K, 4, 2), against K boxes (K, 4, 2)
    → (K,) bool (touching counts)."""
    if len(others) == 0:
        return np.zeros(0, dtype=bool)
    a = np.broadcast_to(box, others.shape)
    overlap = np.ones(len(others), dtype=bool)
    for poly in (a, others):
        for edge in range(2):
            axis = poly[:, edge + 1] - poly[:, edge]
            axis = np.stack([-axis[:, 1], axis[:, 0]], axis=1)
            pa = np.einsum("kij,kj->ki", a, axis)
            pb = np.einsum("kij,kj->ki", others, axis)
            overlap &= (pa.max(1) >= pb.min(1)) & (pb.max(1) >= pa.min(1))
    return overlap


@functools.lru_cache(maxsize=64)
def _footprint_offsets(length: float, width: float, n_long: int, n_lat: int) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame offsets (P,), (P,) [m] of :func:`footprint_points` (one per vehicle size, cached)."""
    u = (np.arange(n_long) + 0.5) / n_long - 0.5
    v = (np.arange(n_lat) + 0.5) / n_lat - 0.5
    uu, vv = np.meshgrid(u * length, v * width, indexing="ij")
    return uu.ravel(), vv.ravel()


def footprint_points(xy: np.ndarray, yaw: float, length: float, width: float, n_long: int = 5, n_lat: int = 3) -> np.ndarray:
    """A regular grid of n_long × n_lat points (P, 2) covering a box evenly (each stands for 1/P of its area)."""
    uu, vv = _footprint_offsets(float(length), float(width), n_long, n_lat)
    c, s = math.cos(yaw), math.sin(yaw)
    out = np.empty((len(uu), 2))
    out[:, 0] = xy[0] + c * uu - s * vv
    out[:, 1] = xy[1] + s * uu + c * vv
    return out


def footprints_points(xy: np.ndarray, yaw: list[float], length: list[float], width: list[float], n_long: int = 5,
                      n_lat: int = 3) -> np.ndarray:
    """:func:`footprint_points` of N boxes at once (N, P, 2): centres (N, 2) [m], headings, lengths and widths
    (N,) [rad, m]; row ``n`` equal to ``footprint_points`` of box ``n``."""
    offsets = [_footprint_offsets(float(a), float(b), n_long, n_lat) for a, b in zip(length, width)]
    uu = np.stack([o[0] for o in offsets])
    vv = np.stack([o[1] for o in offsets])
    c = np.array([math.cos(y) for y in yaw])[:, None]
    s = np.array([math.sin(y) for y in yaw])[:, None]
    out = np.empty((len(uu), uu.shape[1], 2))
    out[:, :, 0] = xy[:, 0:1] + c * uu - s * vv
    out[:, :, 1] = xy[:, 1:2] + s * uu + c * vv
    return out


def stop_line_of(lane_shape: np.ndarray, lane_width: float) -> tuple[np.ndarray, np.ndarray]:
    """The stop line at the end of a lane: its ends (2, 2) [m] (right end, then left end, seen in the
    direction of travel) and the unit travel direction (2,) there. The line runs across the lane's full
    ``lane_width`` [m], perpendicular to the lane's last shape segment ``lane_shape`` (N, 2) [m]."""
    ex, ey = float(lane_shape[-1, 0]), float(lane_shape[-1, 1])
    sx, sy = ex - float(lane_shape[-2, 0]), ey - float(lane_shape[-2, 1])
    norm = max(math.hypot(sx, sy), 1e-9)
    dx, dy = sx / norm, sy / norm
    half = lane_width / 2
    lx, ly = -dy * half, dx * half  # the left offset, in scalars: R_t and the detectors ask every step
    return np.array([[ex - lx, ey - ly], [ex + lx, ey + ly]]), np.array([dx, dy])


def crosses_line(p: np.ndarray, q: np.ndarray, ends: np.ndarray, direction: np.ndarray) -> bool:
    """True when the move ``p`` → ``q`` (2,) [m] crosses the line segment ``ends`` (2, 2) [m] forwards.

    Forwards: ``p`` strictly behind the line and ``q`` on or past it along ``direction`` (2,), the unit
    normal of the line; the crossing point must lie on the segment (ends included). Exact for any step
    length, so a fast mover cannot jump over the line between two samples."""
    before = float((p - ends[0]) @ direction)
    after = float((q - ends[0]) @ direction)
    if not (before < 0.0 <= after):
        return False
    x = p + (q - p) * (before / (before - after))
    span = ends[1] - ends[0]
    along = float((x - ends[0]) @ span) / max(float(span @ span), 1e-18)
    return 0.0 <= along <= 1.0


def points_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd ray test of points (P, 2) against a closed polygon (N, 2) → (P,) bool."""
    x, y = points[:, 0:1], points[:, 1:2]
    a, b = polygon, np.roll(polygon, -1, axis=0)
    crosses = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return (np.sum(crosses & (x < x_at), axis=1) % 2) == 1


class SegmentGrid:
    """A uniform grid over boxes, built once: which boxes may meet a query box (a spatial index).

    Args:
        lo, hi: (M, 2) lower-left and upper-right corners of M boxes [m].
        cell_m: side of a grid cell [m].

    :meth:`query` returns, in ascending order, every box whose cells meet the query box's cells: a
    superset of the boxes that overlap it (the caller tests those exactly), found in time that does
    not grow with the map.
    """

    def __init__(self, lo: np.ndarray, hi: np.ndarray, cell_m: float = 16.0):
        if not cell_m > 0:
            raise ValueError(f"cell_m must be > 0, got {cell_m!r}")
        self.cell_m = float(cell_m)
        self.origin = lo.min(axis=0) if len(lo) else np.zeros(2)
        c_lo = self._cell(lo)
        c_hi = self._cell(hi)
        self.shape = (c_hi.max(axis=0) + 1) if len(lo) else np.ones(2, dtype=np.intp)
        cells, items = [], []
        for k in range(len(lo)):
            cx, cy = np.meshgrid(np.arange(c_lo[k, 0], c_hi[k, 0] + 1), np.arange(c_lo[k, 1], c_hi[k, 1] + 1))
            cells.append((cx * self.shape[1] + cy).ravel())
            items.append(np.full(cx.size, k))
        cells = np.concatenate(cells) if cells else np.zeros(0, dtype=np.intp)
        items = np.concatenate(items) if items else np.zeros(0, dtype=np.intp)
        order = np.lexsort((items, cells))
        self.items = items[order]
        self.starts = np.searchsorted(cells[order], np.arange(int(np.prod(self.shape)) + 1))

    def _cell(self, xy: np.ndarray) -> np.ndarray:
        return np.floor((xy - self.origin) / self.cell_m).astype(np.intp)  # as math.floor in query

    def query(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Indices (ascending, unique) of the boxes whose cells meet the box ``lo``–``hi`` (2,) [m]."""
        ox, oy, cell = self.origin[0], self.origin[1], self.cell_m
        nx, ny = int(self.shape[0]), int(self.shape[1])
        x0 = max(math.floor((lo[0] - ox) / cell), 0)
        y0 = max(math.floor((lo[1] - oy) / cell), 0)
        x1 = min(math.floor((hi[0] - ox) / cell), nx - 1)
        y1 = min(math.floor((hi[1] - oy) / cell), ny - 1)
        if x1 < x0 or y1 < y0:
            return self.items[:0]
        starts = self.starts
        if x0 == x1 and y0 == y1:  # the usual case for a footprint: one cell, already sorted
            return self.items[starts[x0 * ny + y0]:starts[x0 * ny + y0 + 1]]
        parts = [self.items[starts[cx * ny + y0]:starts[cx * ny + y1 + 1]] for cx in range(x0, x1 + 1)]
        return np.unique(np.concatenate(parts))


JUNCTION_LANE = -1
"""``LaneLocator.lane_index`` of a segment of a junction (internal) lane."""


class LaneLocator:
    """Which drivable lane (and which way it runs) lies under given points, and which points lie in a junction.

    Built once per network: every segment of every drivable lane, normal and junction (internal), with its
    half width and unit direction in a :class:`SegmentGrid`, plus the junction polygons; stop lines on demand.
    The junction is its polygon and the surface of its junction lanes: imported maps draw junction lanes
    along the source's connecting roads, which can leave the polygon netconvert computes (a bend joined at a
    node, a crossing guessed there), and a car on its own junction lane is on the road there.
    """

    def __init__(self, net: RoadNetwork):
        self.net = net
        self._stop_lines: dict[tuple[str, str | None], tuple | None] = {}
        starts, ends, half, lane_ids = [], [], [], []
        names = list(net.lanes)
        lanes = [net.lanes[n] for n in names] + list(net.internal_lanes.values())
        for k, lane in enumerate(lanes):
            starts.append(lane.shape[:-1])
            ends.append(lane.shape[1:])
            half.append(np.full(len(lane.shape) - 1, lane.width / 2))
            lane_ids.append(np.full(len(lane.shape) - 1, k if k < len(names) else JUNCTION_LANE))
        self.lane_names = names
        self.a = np.concatenate(starts)
        self.b = np.concatenate(ends)
        self.half_width = np.concatenate(half)
        self.lane_index = np.concatenate(lane_ids)
        """(M,) the normal lane (index into ``lane_names``) of each segment; ``JUNCTION_LANE`` for a segment of
        a junction (internal) lane."""
        ab = self.b - self.a
        self.seg_len = np.maximum(np.hypot(ab[:, 0], ab[:, 1]), 1e-9)
        self.unit = ab / self.seg_len[:, None]
        self.lo = np.minimum(self.a, self.b) - self.half_width[:, None]
        self.hi = np.maximum(self.a, self.b) + self.half_width[:, None]
        self._bounds = np.ascontiguousarray(np.concatenate([self.hi, -self.lo], axis=1))
        """(M, 4) [hi_x, hi_y, -lo_x, -lo_y]: one comparison culls the segments far from the points."""
        self._grid = SegmentGrid(self.lo, self.hi)
        self.lane_edge = np.array([net.lanes[n].edge for n in names] + [""])  # [-1]: the junction lanes'
        self.junctions = list(net.junction_shapes.values())
        self.junction_lo = np.array([j.min(0) for j in self.junctions]).reshape(-1, 2)
        self.junction_hi = np.array([j.max(0) for j in self.junctions]).reshape(-1, 2)
        # the compiled lookup's forms of the same data: edges as numbers, junction polygons stacked
        edges = sorted(set(self.lane_edge.tolist()))
        self._edge_number = {edge: k for k, edge in enumerate(edges)}
        self._segment_edge = np.array([self._edge_number[e] for e in self.lane_edge], dtype=np.int64)[self.lane_index]
        self._junction_xy = np.ascontiguousarray(
            np.concatenate([np.asarray(j, dtype=float).reshape(-1, 2) for j in self.junctions]) if self.junctions
            else np.zeros((0, 2)))
        self._junction_start = np.concatenate([[0], np.cumsum([len(j) for j in self.junctions])]).astype(np.int64)

    def stop_line(self, lane_id: str, next_edge: str | None) -> tuple[np.ndarray, np.ndarray, str, int] | None:
        """The signalised stop line at the end of the normal lane ``lane_id`` on the way to ``next_edge``.

        The link is the lane's link onto ``next_edge``, else the lane's first link (where a lane that
        does not continue the route leads, as :meth:`RoadNetwork.follow`). Returns (ends (2, 2) [m],
        travel direction (2,), tls id, link index), or None where that link has no traffic light or
        the lane is unknown (cached per (lane, next edge))."""
        key = (lane_id, next_edge)
        if key not in self._stop_lines:
            self._stop_lines[key] = self._find_stop_line(lane_id, next_edge)
        return self._stop_lines[key]

    def _find_stop_line(self, lane_id: str, next_edge: str | None):
        lane = self.net.lanes.get(lane_id)
        if lane is None:
            return None
        options = self.net.lane_next.get(lane_id, ())
        to_edge = next((edge for _, edge in options if edge == next_edge), options[0][1] if options else None)
        link = next((c for c in self.net.connections.get(lane.edge, ()) if c.from_lane == lane_id and c.to_edge == to_edge), None)
        if link is None or not link.tls or link.link_index < 0:
            return None
        ends, direction = stop_line_of(lane.shape, lane.width)
        return ends, direction, link.tls, link.link_index

    def segment_is_edge(self, segments: np.ndarray, edge: str) -> np.ndarray:
        """(len(segments),) bool: which of the given segment indices belong to lanes of ``edge``."""
        return self.lane_edge[self.lane_index[segments]] == edge

    def locate(self, points: np.ndarray, prefer_edge: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For points (P, 2): (normal lane index into ``lane_names`` or -1, lane direction (P, 2), in_junction (P,)
        bool: in a junction polygon, or on a junction lane and on no normal lane).

        A point on a lane of ``prefer_edge`` (the ego's own edge) is assigned to it even where another
        lane lies under it in plan view (a ramp bridging a carriageway). Compiled
        (:func:`.locate_kernel.locate_points`); :meth:`locate_reference` is its numpy form (equal results)."""
        from hbmp_bench.metrics.locate_kernel import locate_points  # numba loads on the first call

        points = np.ascontiguousarray(points, dtype=float)
        candidates = self._grid.query(points.min(0), points.max(0))
        return locate_points(points, candidates, self._bounds, self.a, self.unit, self.seg_len, self.half_width,
                             self.lane_index, self._segment_edge, self._edge_number.get(prefer_edge, -1) if prefer_edge
                             else -1, self.junction_lo, self.junction_hi, self._junction_xy, self._junction_start)

    def locate_all(self, points: np.ndarray, prefer_edges: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`locate` of N footprints at once: points (N, P, 2), ``prefer_edges`` one per footprint;
        returns (N, P), (N, P, 2), (N, P), row ``n`` equal to ``locate(points[n], prefer_edges[n])``
        (one compiled call, :func:`.locate_kernel.locate_footprints`)."""
        from hbmp_bench.metrics.locate_kernel import locate_footprints

        grid = self._grid
        prefer = np.array([self._edge_number.get(e, -1) if e else -1 for e in prefer_edges], dtype=np.int64)
        return locate_footprints(np.ascontiguousarray(points, dtype=float), prefer, grid.origin, grid.cell_m,
                                 int(grid.shape[0]), int(grid.shape[1]), grid.items, grid.starts, self._bounds, self.a,
                                 self.unit, self.seg_len, self.half_width, self.lane_index, self._segment_edge,
                                 self.junction_lo, self.junction_hi, self._junction_xy, self._junction_start)

    def locate_reference(self, points: np.ndarray, prefer_edge: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`locate` in numpy (what the compiled form is tested against)."""
        p_lo, p_hi = points.min(0), points.max(0)
        candidates = self._grid.query(p_lo, p_hi)
        near = candidates[(self._bounds[candidates] >= np.concatenate([p_lo, -p_hi])).all(axis=1)]
        lane = np.full(len(points), -1)
        direction = np.zeros((len(points), 2))
        if len(near):
            a, u, L = self.a[near], self.unit[near], self.seg_len[near]
            px, py = points[:, 0:1], points[:, 1:2]
            t = (px - a[:, 0]) * u[:, 0] + (py - a[:, 1]) * u[:, 1]  # (P, M) along each segment
            np.minimum(np.maximum(t, 0.0, out=t), L, out=t)
            dist = np.hypot(px - (a[:, 0] + t * u[:, 0]), py - (a[:, 1] + t * u[:, 1]))
            inside = dist <= self.half_width[near][None]
            junction_lane = (inside & (self.lane_index[near] < 0)[None]).any(axis=1)
            inside &= (self.lane_index[near] >= 0)[None]
            if prefer_edge:
                own = inside & self.segment_is_edge(near, prefer_edge)[None]
                inside = np.where(own.any(axis=1, keepdims=True), own, inside)
            dist = np.where(inside, dist, np.inf)
            best = np.argmin(dist, axis=1)
            hit = np.isfinite(dist[np.arange(len(points)), best])
            lane[hit] = self.lane_index[near[best[hit]]]
            direction[hit] = u[best[hit]]
        in_junction = (lane < 0) & junction_lane if len(near) else np.zeros(len(points), dtype=bool)
        jnear = np.nonzero(np.all(self.junction_hi >= p_lo, axis=1) & np.all(self.junction_lo <= p_hi, axis=1))[0]
        for j in jnear:
            in_junction |= points_in_polygon(points, self.junctions[j])
        return lane, direction, in_junction
