"""Speed limits that a car can hold through a lane's bends: an import's advisory curve speeds.

SUMO's drivers keep a lane's speed limit through its bends whatever their radius; netconvert limits only
its junction lanes (to 5.5 m/s² by default). OpenDRIVE maps draw bends as roads of their own (CARLA's
Town02: 50 km/h through 8 m radii), so SUMO's driver took them at 24 m/s². An import lowers each drivable
lane's speed limit, normal and junction lanes alike, to :func:`curve_speed`: the highest speed at which
the lane's sharpest bend gives at most ``LATERAL_ACCEL_MAX_MPS2`` averaged over one second of driving
(the measure of :class:`~hbmp_bench.metrics.episode.LateralAcceleration`). SUMO's drivers brake for a
lower limit ahead; the ego's speed_up stops at its lane's limit.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .lanetypes import allows

LATERAL_ACCEL_MAX_MPS2 = 4.0
"""Lateral acceleration a bend may ask of a car at its speed limit [m/s²] (the motion planner's own limit)."""
CURVE_WINDOW_S = 1.0
"""The bend is measured over the arc a car drives in this long [s] (``metrics.episode.LATERAL_WINDOW_S`` is it)."""
MIN_CURVE_SPEED_MPS = 2.0
"""No curve speed below this [m/s]: the tightest junction turns (radius ~1 m) are still driven."""
SPEED_STEP_MPS = 0.1
"""Curve speeds are multiples of this [m/s] below the lane's own limit."""
_SPACING_M = 0.25


def _headings(shape: np.ndarray) -> np.ndarray:
    """Unwrapped headings [rad] of a polyline resampled every ``_SPACING_M``."""
    seg = np.hypot(*np.diff(shape, axis=0).T)
    pts = shape[np.append(True, seg > 1e-9)]
    if len(pts) < 2:
        return np.zeros(0)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    s = np.append(np.arange(0.0, arc[-1], _SPACING_M), arc[-1])
    x, y = np.interp(s, arc, pts[:, 0]), np.interp(s, arc, pts[:, 1])
    keep = np.append(True, np.hypot(np.diff(x), np.diff(y)) > 1e-9)
    x, y = x[keep], y[keep]
    return np.unwrap(np.arctan2(np.diff(y), np.diff(x)))


def max_turn(headings: np.ndarray, arc_m: float) -> float:
    """The largest heading change [rad] within any ``arc_m`` [m] of a lane (its whole turn when shorter)."""
    if len(headings) < 2:
        return 0.0
    k = int(round(arc_m / _SPACING_M))
    if k >= len(headings) - 1:
        return float(np.ptp(headings))
    k = max(k, 1)
    return float(np.max(np.abs(headings[k:] - headings[:-k])))


def curve_speed(shape: np.ndarray, limit_mps: float, a_max: float = LATERAL_ACCEL_MAX_MPS2,
                window_s: float = CURVE_WINDOW_S) -> float:
    """The highest speed [m/s] ≤ ``limit_mps`` at which the lane ``shape`` (N, 2) [m] asks at most ``a_max``
    [m/s²] of lateral acceleration: speed × (largest heading change within speed × ``window_s`` of arc) /
    ``window_s``, in steps of ``SPEED_STEP_MPS``, never below ``MIN_CURVE_SPEED_MPS`` (nor above the limit)."""
    headings = _headings(np.asarray(shape, dtype=float)[:, :2])
    v = float(limit_mps)
    floor = min(MIN_CURVE_SPEED_MPS, v)
    while v > floor and v * max_turn(headings, v * window_s) / window_s > a_max:
        v = max(round(v - SPEED_STEP_MPS, 6), floor)
    return v


_LANE = re.compile(r'<lane id="(?P<id>[^"]+)"(?P<attrs>[^>]*)>')
_ATTR = re.compile(r'(?P<key>[\w:]+)="(?P<value>[^"]*)"')


def limit_curve_speeds(path: str | Path, a_max: float = LATERAL_ACCEL_MAX_MPS2) -> int:
    """Lower the speed limit of every drivable lane of the SUMO net at ``path`` to its :func:`curve_speed`, in
    place; only the ``speed`` attributes of those lanes change. Returns the number of lanes lowered."""
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    lowered = 0

    def lane(m: re.Match) -> str:
        nonlocal lowered
        attrs = {a.group("key"): a.group("value") for a in _ATTR.finditer(m.group("attrs"))}
        if "speed" not in attrs or "shape" not in attrs or not allows(attrs, "passenger"):
            return m.group(0)
        limit = float(attrs["speed"])
        shape = np.array([[float(c) for c in p.split(",")[:2]] for p in attrs["shape"].split()])
        v = curve_speed(shape, limit, a_max)
        if v >= limit - 1e-9:
            return m.group(0)
        lowered += 1
        return m.group(0).replace(f'speed="{attrs["speed"]}"', f'speed="{v:.2f}"', 1)

    path.write_text(_LANE.sub(lane, text), encoding="utf-8")
    return lowered


__all__ = ["LATERAL_ACCEL_MAX_MPS2", "curve_speed", "limit_curve_speeds", "max_turn"]

