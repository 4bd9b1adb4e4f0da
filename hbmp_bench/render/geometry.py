"""Polyline helpers of the renderer (pure numpy): offsets, dashes, oriented boxes.

Coordinates are world metres (x east, y north); polylines are ``(N, 2)`` arrays.
"""

from __future__ import annotations

import numpy as np


def offset_polyline(shape: np.ndarray, distance: float) -> np.ndarray:
    """The polyline (N, 2) shifted ``distance`` [m] to its LEFT (negative: right).

    Vertices move along the bisector of their two segments' normals (miter join, the
    shift is limited to 4x ``distance`` at sharp corners), so parallel lane borders stay
    parallel through bends.
    """
    shape = np.asarray(shape, dtype=float)
    seg = np.diff(shape, axis=0)
    seg_len = np.hypot(seg[:, 0], seg[:, 1])
    keep = seg_len > 1e-9
    if not keep.any():
        return shape.copy()
    tangent = np.zeros_like(seg)
    tangent[keep] = seg[keep] / seg_len[keep, None]
    # carry the last valid tangent over zero-length segments
    for i in range(len(tangent)):
        if not keep[i]:
            tangent[i] = tangent[i - 1] if i > 0 and keep[i - 1] else tangent[keep][0]
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    vertex_normal = np.empty_like(shape)
    vertex_normal[0], vertex_normal[-1] = normal[0], normal[-1]
    if len(shape) > 2:
        bisector = normal[:-1] + normal[1:]
        norm = np.hypot(bisector[:, 0], bisector[:, 1])
        bisector = np.where(norm[:, None] > 1e-9, bisector / np.maximum(norm, 1e-9)[:, None], normal[1:])
        cos_half = np.clip(np.sum(bisector * normal[1:], axis=1), 0.25, 1.0)
        vertex_normal[1:-1] = bisector / cos_half[:, None]
    return shape + distance * vertex_normal


def dashes(shape: np.ndarray, on: float, off: float) -> list[np.ndarray]:
    """Pieces (each (M, 2)) of a polyline for a dashed line: ``on`` [m] drawn, ``off`` [m] gap."""
    shape = np.asarray(shape, dtype=float)
    if on <= 0 or off < 0:
        raise ValueError(f"dash lengths must be on > 0, off >= 0 [m], got {on}, {off}")
    seg = np.diff(shape, axis=0)
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))])
    total = cum[-1]
    pieces = []
    start = 0.0
    while start < total:
        stop = min(start + on, total)
        inside = (cum > start) & (cum < stop)
        s = np.concatenate([[start], cum[inside], [stop]])
        pts = np.stack([np.interp(s, cum, shape[:, 0]), np.interp(s, cum, shape[:, 1])], axis=1)
        if stop - start > 1e-6:
            pieces.append(pts)
        start += on + off
    return pieces


def box_corners(xy: np.ndarray, yaw: np.ndarray, length: np.ndarray, width: np.ndarray) -> np.ndarray:
    """Corners (K, 4, 2) [m] of K oriented rectangles centred at ``xy`` (K, 2).

    Order: front-left, front-right, rear-right, rear-left.
    """
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    yaw = np.asarray(yaw, dtype=float).reshape(-1)
    hl = 0.5 * np.asarray(length, dtype=float).reshape(-1)
    hw = 0.5 * np.asarray(width, dtype=float).reshape(-1)
    fwd = np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    left = np.stack([-np.sin(yaw), np.cos(yaw)], axis=1)
    signs = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0]])
    return (xy[:, None, :]
            + signs[None, :, 0:1] * (hl[:, None, None] * fwd[:, None, :])
            + signs[None, :, 1:2] * (hw[:, None, None] * left[:, None, :]))
