"""Curvilinear (Frenet) frame on a polyline lane centerline.

A :class:`Path` is an immutable polyline ``(N, 2)`` of ``x, y`` [m] with

* ``s``       (N,)  cumulative arc length [m] (starting at ``s_start``),
* ``heading`` (N,)  tangent direction at each vertex [rad] (mean of the two adjacent
  segment directions; the end vertices take their segment's direction),
* ``kappa``   (N,)  signed curvature at each vertex [1/m], positive for a left turn: the
  turning angle at the vertex divided by the mean length of its two segments (a discrete
  ``d heading / ds``, exact in total turning), smoothed with ``smooth`` passes of a
  ``[1, 2, 1] / 4`` filter. The input polyline is first densified to at most
  ``max_spacing`` [m] per segment so the smoothing acts over ~metres of arc length and a
  kink at a lane joint does not leak curvature along a long straight segment.

Between vertices the position follows the chord, while heading and curvature are
interpolated linearly (so both are continuous along ``s``). Before the first vertex and
after the last one the path is extended straight along its end segments, so ``project``
and ``point_at`` are defined everywhere (``s`` may be < ``s[0]`` or > ``s[-1]``).

Sign conventions: angles are counter-clockwise from +x; the lateral error ``e`` is
positive to the LEFT of the path direction; ``theta_e = yaw - heading`` wrapped to
``(-pi, pi]``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

__all__ = ["Path", "UniformSegments", "wrap_angle"]


class UniformSegments(NamedTuple):
    """Segment arrays of a path resampled at uniform arc-length steps (all (N,) float64).

    ``x0, y0``: segment start [m]; ``tx, ty``: unit tangent; ``chord``: chord length [m];
    ``s``: arc length at the start [m]; ``s_per_m``: arc length per chord metre (chords across
    a kink are shorter than the step); ``heading, kappa``: at the start [rad, 1/m]; ``dh, dk``:
    their change along the segment. ``inv_ds``: 1 / step [1/m].
    """

    x0: np.ndarray
    y0: np.ndarray
    tx: np.ndarray
    ty: np.ndarray
    chord: np.ndarray
    s: np.ndarray
    s_per_m: np.ndarray
    heading: np.ndarray
    kappa: np.ndarray
    dh: np.ndarray
    dk: np.ndarray
    inv_ds: float


def wrap_angle(a):
    """Wrap angles [rad] to ``(-pi, pi]`` (array or scalar, same shape)."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=float), 2.0 * np.pi)


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a, dtype=float)
    a.setflags(write=False)
    return a


class Path:
    """Polyline reference path with a curvilinear frame.

    Args:
        xy: ``(N, 2)`` vertices [m], N >= 2 after dropping consecutive points closer than
            ``min_spacing``.
        s_start: arc length of the first vertex [m] (a window cut from a longer path keeps
            the parent's ``s``).
        smooth: number of ``[1, 2, 1] / 4`` smoothing passes applied to the curvature.
        min_spacing: consecutive vertices closer than this [m] are merged.
        max_spacing: longer segments are split evenly to at most this length [m]
            (``None`` keeps the vertices as given).

    Raises:
        ValueError: bad shape, non-finite values, fewer than 2 distinct vertices, bad
            ``smooth`` / ``min_spacing``.
    """

    __slots__ = (
        "xy", "s", "heading", "kappa",
        "_x0", "_y0", "_tx", "_ty", "_seg_len", "_lo", "_hi", "_dh", "_dk", "_uniform", "_segments",
        "_s_start", "_heading_start",
    )

    def __init__(self, xy, *, s_start: float = 0.0, smooth: int = 2, min_spacing: float = 1e-3,
                 max_spacing: float | None = 1.0):
        xy = np.asarray(xy, dtype=float)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"xy must have shape (N, 2), got {xy.shape}")
        if not np.all(np.isfinite(xy)):
            raise ValueError("xy must be finite")
        if not np.isfinite(s_start):
            raise ValueError("s_start must be finite")
        if int(smooth) != smooth or smooth < 0:
            raise ValueError(f"smooth must be a non-negative int, got {smooth!r}")
        if not min_spacing >= 0:
            raise ValueError(f"min_spacing must be >= 0, got {min_spacing!r}")
        if max_spacing is not None and not max_spacing > min_spacing:
            raise ValueError(f"max_spacing must be > min_spacing or None, got {max_spacing!r}")
        xy = _dedup(xy, min_spacing)
        if len(xy) < 2:
            raise ValueError("a Path needs at least 2 distinct vertices")
        if max_spacing is not None:
            xy = _densify(xy, max_spacing)
        d = np.diff(xy, axis=0)
        seg_len = np.hypot(d[:, 0], d[:, 1])
        s = s_start + np.concatenate(([0.0], np.cumsum(seg_len)))
        t = d / seg_len[:, None]
        # vertex headings: mean direction of adjacent segments
        hv = np.empty((len(xy), 2))
        hv[0], hv[-1] = t[0], t[-1]
        hv[1:-1] = t[:-1] + t[1:]
        cusp = np.hypot(hv[:, 0], hv[:, 1]) < 1e-9
        hv[1:-1][cusp[1:-1]] = t[1:][cusp[1:-1]]
        heading = np.arctan2(hv[:, 1], hv[:, 0])
        # curvature: turning angle at a vertex / mean adjacent segment length (d psi / ds)
        kappa = np.zeros(len(xy))
        if len(xy) >= 3:
            seg_h = np.arctan2(t[:, 1], t[:, 0])
            kappa[1:-1] = wrap_angle(np.diff(seg_h)) / (0.5 * (seg_len[:-1] + seg_len[1:]))
            kappa[0], kappa[-1] = kappa[1], kappa[-2]
            for _ in range(int(smooth)):
                p = np.concatenate(([kappa[0]], kappa, [kappa[-1]]))
                kappa = 0.25 * p[:-2] + 0.5 * p[1:-1] + 0.25 * p[2:]
        self._init_arrays(xy, s, heading, kappa)

    # ------------------------------------------------------------------ construction
    def _init_arrays(self, xy, s, heading, kappa) -> None:
        d = np.diff(xy, axis=0)
        # chord lengths (== diff(s) except on resampled windows, where s is the parent's arc
        # length and a chord may cut a corner by a hair); tangents are unit vectors
        seg_len = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)
        self.xy = _readonly(xy)
        self.s = _readonly(s)
        self.heading = _readonly(heading)
        self.kappa = _readonly(kappa)
        self._seg_len = _readonly(seg_len)
        self._tx = _readonly(d[:, 0] / seg_len)
        self._ty = _readonly(d[:, 1] / seg_len)
        lo = np.zeros(len(seg_len))
        hi = seg_len.copy()
        lo[0], hi[-1] = -np.inf, np.inf  # straight extension beyond both ends
        self._lo, self._hi = _readonly(lo), _readonly(hi)
        self._dh = _readonly(wrap_angle(np.diff(heading)))
        self._dk = _readonly(np.diff(kappa))
        self._x0 = _readonly(xy[:-1, 0])
        self._y0 = _readonly(xy[:-1, 1])
        self._uniform: UniformSegments | None = None
        self._segments = (self.s, self._x0, self._y0, self._tx, self._ty, self._seg_len, self.heading, self.kappa,
                          self._dh, self._dk)
        self._s_start = self.s[:-1]  # of each segment
        self._heading_start = self.heading[:-1]

    @classmethod
    def _from_arrays(cls, xy, s, heading, kappa) -> Path:
        obj = cls.__new__(cls)
        obj._init_arrays(np.asarray(xy, float), np.asarray(s, float),
                         np.asarray(heading, float), np.asarray(kappa, float))
        return obj

    @classmethod
    def concat(cls, polylines: Sequence, *, joint_tol: float = 0.05, **kwargs) -> Path:
        """Join lane polylines (lane -> junction internal lane -> next lane) into one path.

        Args:
            polylines: sequence of ``(N_i, 2)`` arrays [m]; ``None`` / empty items are
                skipped.
            joint_tol: the first point of a polyline is dropped when it lies within this
                distance [m] of the previous polyline's last point (duplicate joint).
            **kwargs: passed to :class:`Path` (``smooth``, ``min_spacing``, ``s_start``).
        """
        if not joint_tol >= 0:
            raise ValueError(f"joint_tol must be >= 0, got {joint_tol!r}")
        parts: list[np.ndarray] = []
        for p in polylines:
            if p is None:
                continue
            p = np.asarray(p, dtype=float).reshape(-1, 2)
            if len(p) == 0:
                continue
            if parts and np.hypot(*(p[0] - parts[-1][-1])) <= joint_tol:
                p = p[1:]
            if len(p):
                parts.append(p)
        if not parts:
            raise ValueError("Path.concat needs at least one non-empty polyline")
        return cls(np.concatenate(parts, axis=0), **kwargs)

    def resample(self, ds: float, s_from: float | None = None, s_to: float | None = None,
                 extrapolate: bool = False) -> Path:
        """Uniformly spaced copy of ``[s_from, s_to]`` with spacing ``ds`` [m].

        Heading and curvature are interpolated from this path (not re-estimated from the
        resampled chords), and ``s`` keeps this path's values. The window is clipped to the
        path unless ``extrapolate`` (then it may extend straight past either end).
        """
        if not ds > 0:
            raise ValueError(f"ds must be > 0, got {ds!r}")
        a = self.s[0] if s_from is None else float(s_from)
        b = self.s[-1] if s_to is None else float(s_to)
        if not extrapolate:
            a, b = max(a, self.s[0]), min(b, self.s[-1])
            if b - a < 1e-6:  # window outside the path: keep a short piece at the nearer end
                a, b = (self.s[-1] - ds, self.s[-1]) if a >= self.s[-1] else (self.s[0], self.s[0] + ds)
        if not b - a > 0:
            raise ValueError(f"empty resampling window [{a}, {b}]")
        n = max(int(np.ceil((b - a) / ds)), 1)
        s = np.linspace(a, b, n + 1)
        x, y, h, k = self.point_at(s)
        return Path._from_arrays(np.stack([x, y], axis=1), s, h, k)

    # ------------------------------------------------------------------ properties
    @property
    def length(self) -> float:
        """Total arc length [m]."""
        return float(self.s[-1] - self.s[0])

    @property
    def n_segments(self) -> int:
        return len(self._seg_len)

    def __repr__(self) -> str:
        return f"Path(n={len(self.s)}, s=[{self.s[0]:.2f}, {self.s[-1]:.2f}] m)"

    # ------------------------------------------------------------------ queries
    def _segment_of(self, s: np.ndarray) -> np.ndarray:
        i = np.searchsorted(self.s, s, side="right") - 1
        return np.minimum(np.maximum(i, 0), len(self._seg_len) - 1)

    def _interp(self, i: np.ndarray, c: np.ndarray):
        """Heading (not wrapped) and curvature at offset ``c`` [m] along segment ``i``."""
        frac = np.minimum(np.maximum(c / self._seg_len[i], 0.0), 1.0)
        h = self.heading[i] + frac * self._dh[i]
        k = self.kappa[i] + frac * self._dk[i]
        return h, k

    def point_at(self, s):
        """Pose on the path at arc length ``s`` (array (M,) or scalar) [m].

        Returns:
            ``(x, y, heading, kappa)``, each shaped like ``s``: position [m], tangent
            heading [rad], curvature [1/m]. Outside ``[s[0], s[-1]]`` the end segments are
            extended straight.
        """
        s = np.asarray(s, dtype=float)
        i = self._segment_of(s)
        c = s - self.s[i]
        x = self.xy[i, 0] + c * self._tx[i]
        y = self.xy[i, 1] + c * self._ty[i]
        h, k = self._interp(i, c)
        return x, y, wrap_angle(h), k

    def _nearest(self, px: np.ndarray, py: np.ndarray, idx: np.ndarray):
        """Nearest candidate segment for each point.

        Args:
            px, py: (M, 1) point coordinates [m].
            idx: (M, K) or (1, K) candidate segment indices.

        Returns:
            ``(i, c, e)`` (M,): chosen segment (nearest by true distance to the polyline),
            offset along it [m] (clipped to the segment except beyond the path ends, where
            the end segment is extended), signed distance [m] (left positive; beyond the
            ends the perpendicular offset from the extended end segment).
        """
        x0, y0, tx, ty = self._x0[idx], self._y0[idx], self._tx[idx], self._ty[idx]
        dx = px - x0
        dy = py - y0
        along = dx * tx + dy * ty
        cross = tx * dy - ty * dx
        c = np.minimum(np.maximum(along, 0.0), self._seg_len[idx])
        d2 = along - c
        d2 *= d2
        d2 += cross * cross
        m, k = d2.shape
        flat = d2.argmin(axis=1)
        flat += np.arange(0, m * k, k)
        i = (idx.ravel()[flat] if idx.shape[0] == m else idx[0, flat % k])
        return (i,) + _report(along.ravel()[flat], cross.ravel()[flat], c.ravel()[flat],
                              d2.ravel()[flat], self._lo[i], self._hi[i])

    def _candidates(self, m: int, hint_s, window: tuple[float, float]) -> np.ndarray:
        if hint_s is None:
            return np.arange(self.n_segments)[None, :]
        back, ahead = window
        if not (back >= 0 and ahead >= 0):
            raise ValueError(f"window must be (back >= 0, ahead >= 0), got {window!r}")
        h = np.asarray(hint_s, dtype=float)
        if h.ndim > 0 and h.shape != (m,):
            raise ValueError(f"hint_s must be a scalar or shape ({m},), got {h.shape}")
        lo = float(np.min(h)) - back
        hi = float(np.max(h)) + ahead
        i0 = int(self._segment_of(lo))
        i1 = int(self._segment_of(hi))
        return np.arange(i0, i1 + 1)[None, :]

    def segment_arrays(self) -> tuple[np.ndarray, ...]:
        """``(s, x0, y0, tx, ty, chord, heading, kappa, dh, dk)``, what the compiled planner reads
        (:func:`.plan_kernel.plan_samples`): vertex arc length [m], heading [rad] and curvature [1/m] (N,);
        segment start [m], unit tangent, chord [m] and the change of heading and curvature along it (N - 1,).
        Read-only views of the path's own arrays."""
        return self._segments

    def uniform_segments(self) -> UniformSegments:
        """Segment arrays for the compiled roll-out (:func:`.rollout.roll_out`).

        Raises:
            ValueError: the path is not resampled at uniform arc-length steps (build it with
                ``resample(..., extrapolate=True)`` over the whole region points can reach:
                the roll-out's projection does not extend the ends).
        """
        cached = getattr(self, "_uniform", None)
        if cached is not None:  # the path is immutable: computed once
            return cached
        step = np.diff(self.s)
        ds = float(np.mean(step))
        if np.ptp(step) > 1e-6 * ds:
            raise ValueError("uniform_segments needs a path resampled at uniform arc-length steps")
        # Resampling a kinked polyline keeps s uniform, but chords across a kink are shorter
        # than ds: clip along each chord and convert chord metres to arc length per segment.
        self._uniform = UniformSegments(
            x0=self._x0, y0=self._y0, tx=self._tx, ty=self._ty, chord=self._seg_len,
            s=self.s[:-1], s_per_m=step / self._seg_len, heading=self.heading[:-1],
            kappa=self.kappa[:-1], dh=self._dh, dk=self._dk, inv_ds=1.0 / ds)
        return self._uniform

    def frenet(self, xy, hint_s=None, window: tuple[float, float] = (10.0, 40.0)):
        """Arc length and signed lateral offset of points.

        Args:
            xy: ``(M, 2)`` (or ``(2,)``) positions [m].
            hint_s: optional previous arc length [m] (scalar or (M,)); only segments
                within ``[min(hint_s) - window[0], max(hint_s) + window[1]]`` are searched.
                Use it on looping paths and for speed.
            window: ``(back, ahead)`` [m] search window around ``hint_s``.

        Returns:
            ``(s, e)``: (M,) arc length [m], lateral offset [m] (left positive).
        """
        s, e, _, _ = self._project(xy, hint_s, window)
        return s, e

    def _project(self, xy, hint_s, window):
        xy = np.asarray(xy, dtype=float)
        single = xy.ndim == 1
        xy = xy.reshape(-1, 2)
        idx = self._candidates(len(xy), hint_s, window)
        i, c, e = self._nearest(xy[:, :1], xy[:, 1:], idx)
        h, k = self._interp(i, c)
        h = wrap_angle(h)
        s = self.s[i] + c
        if single:
            return s[0], e[0], h[0], k[0]
        return s, e, h, k

    def project_pose(self, x: float, y: float, yaw: float, hint_s: float | None = None):
        """:meth:`project` of one pose [m, m, rad] with the default window, compiled
        (:func:`.plan_kernel.project_pose`, numba loads on the first call): the same four floats, to the bit,
        without ~20 small numpy operations (the executor's finish check runs it every control period)."""
        from .plan_kernel import project_pose

        return project_pose(float(x), float(y), float(yaw), np.nan if hint_s is None else float(hint_s),
                            *self._segments)

    def project_poses(self, xy: np.ndarray, yaw: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`project` of M poses without a hint, compiled (:func:`.obstacle_kernels.project_poses`, numba
        loads on the first call): ``(s, e, theta_e)``, each (M,) [m, m, rad], the same floats.

        Args:
            xy: (M, 2) positions [m]; yaw: (M,) headings [rad]."""
        from .obstacle_kernels import project_poses

        xy = np.asarray(xy, dtype=float)
        return project_poses(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
                             np.ascontiguousarray(yaw, dtype=float), self._x0, self._y0, self._tx, self._ty,
                             self._seg_len, self._s_start, self._heading_start, self._dh)

    def project(self, xy, yaw, hint_s=None, window: tuple[float, float] = (10.0, 40.0)):
        """Project poses onto the path (nearest segment).

        Args:
            xy: ``(M, 2)`` positions [m] (or one ``(2,)`` point -> scalar outputs).
            yaw: ``(M,)`` headings [rad] (or a scalar broadcast to all points).
            hint_s: optional previous arc length [m] restricting the search window.
            window: ``(back, ahead)`` [m] around ``hint_s``.

        Returns:
            ``(s, e, theta_e, kappa)`` (M,): arc length [m]; lateral error [m], positive
            to the left; heading error ``yaw - heading`` [rad] in ``(-pi, pi]``; path
            curvature [1/m] at the projection.
        """
        s, e, h, k = self._project(xy, hint_s, window)
        theta_e = wrap_angle(np.asarray(yaw, dtype=float) - h)
        if np.ndim(s) == 0:
            return float(s), float(e), float(theta_e), float(k)
        return s, e, np.broadcast_to(theta_e, s.shape).copy(), k


def _report(along, cross, c, d2, lo, hi):
    """Offset and signed distance of the chosen segments, extending the path ends.

    ``c`` is ``along`` clipped to the segment; ``lo``/``hi`` are ``0``/``length`` except
    ``-inf`` on the first and ``+inf`` on the last segment.
    """
    c_rep = np.minimum(np.maximum(along, lo), hi)
    e = np.copysign(np.sqrt(d2), cross)
    ext = c_rep != c
    if ext.any():
        e = np.where(ext, cross, e)
    return c_rep, e


def round_corners(xy: np.ndarray, iterations: int = 3, min_spacing: float = 0.0) -> np.ndarray:
    """Chaikin corner cutting of a polyline (N, 2) -> (M, 2), end points kept.

    Each pass replaces every segment by its 1/4 and 3/4 points, so the curve converges to a
    quadratic B-spline whose distance to the original corner is at most ~1/4 of the shorter
    adjacent segment times the kink's sine. Lane shapes from SUMO bend in few coarse vertices
    (junction lanes: ~4 m chords with ~25 degree kinks); rounding them gives the planner a
    reference with continuous curvature.

    The bend of a kink is spread over its adjacent segments, so a short one bends it within a
    fraction of its length: where a lane meets a junction lane SUMO's shapes repeat a vertex or
    leave one 0.2 m from the kink, and a 23 degree kink there rounds to a curvature of 2 1/m
    (a 0.5 m radius). ``min_spacing`` [m] first drops the vertices closer than that to the
    previously kept one (the last vertex kept), so every kink bends over at least that length.
    """
    pts = np.asarray(xy, dtype=float)
    if iterations < 0:
        raise ValueError(f"iterations must be >= 0, got {iterations!r}")
    if not min_spacing >= 0.0:
        raise ValueError(f"min_spacing must be >= 0 [m], got {min_spacing!r}")
    if min_spacing > 0.0:
        pts = _dedup(pts, min_spacing)
    for _ in range(iterations):  # loop over refinement passes (construction only)
        if len(pts) < 3:
            break
        a, b = pts[:-1], pts[1:]
        q, r = 0.75 * a + 0.25 * b, 0.25 * a + 0.75 * b
        inner = np.stack([q, r], axis=1).reshape(-1, 2)[1:-1]
        pts = np.vstack([pts[:1], inner, pts[-1:]])
    return pts


def _densify(xy: np.ndarray, max_spacing: float) -> np.ndarray:
    """Insert evenly spaced points so that no segment is longer than ``max_spacing``."""
    d = np.diff(xy, axis=0)
    n = np.maximum(np.ceil(np.hypot(d[:, 0], d[:, 1]) / max_spacing - 1e-9).astype(int), 1)
    if np.all(n == 1):
        return xy
    seg = np.repeat(np.arange(len(d)), n)
    frac = np.arange(len(seg)) - np.repeat(np.cumsum(n) - n, n)
    frac = frac / np.repeat(n, n)
    return np.concatenate([xy[seg] + frac[:, None] * d[seg], xy[-1:]], axis=0)


def _dedup(xy: np.ndarray, tol: float) -> np.ndarray:
    """Drop vertices closer than ``tol`` to the previously kept one (keeps the last)."""
    if len(xy) < 2:
        return xy
    keep = [0]
    step = np.hypot(*np.diff(xy, axis=0).T)
    if np.all(step > tol):
        return xy
    last = xy[0]
    for i in range(1, len(xy)):  # loop over vertices (construction only, not per sample)
        if np.hypot(*(xy[i] - last)) > tol:
            keep.append(i)
            last = xy[i]
    if keep[-1] != len(xy) - 1 and len(keep) > 1:
        keep[-1] = len(xy) - 1
    return xy[keep]
