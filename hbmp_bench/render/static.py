"""The static layer of a network: road surface, sidewalks, crossings and lane markings,
rasterised once per (network, scale) with Pillow and cached for the process.

Drivable lanes, junction shapes and opposite edges come from the package's
:class:`~hbmp_bench.maps.roadnet.RoadNetwork`; the pedestrian infrastructure (sidewalks,
walking areas, crossings) is read from the same net file with sumolib, because the lane
graph keeps drivable lanes only.

The image is drawn ``supersample`` times larger and box-filtered down (anti-aliasing).
Pixel coordinates are continuous: pixel ``(c, r)`` covers ``[c, c + 1) x [r, r + 1)``;
world ``(x, y)`` maps to ``((x - x0) / mpp, (y1 - y) / mpp)`` (north up).
"""

from __future__ import annotations

import functools
import math
import weakref
from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw

from hbmp_bench.errors import ConfigError
from hbmp_bench.maps.roadnet import RoadNetwork
from hbmp_bench.render import palette
from hbmp_bench.render.geometry import dashes, offset_polyline

MARKING_WIDTH_M = 0.15
DASH_ON_M, DASH_OFF_M = 3.0, 4.5
ZEBRA_M = 0.5
STATIC_MARGIN_M = 30.0
MAX_STATIC_PIXELS = 150_000_000
"""Largest supersampled canvas (pixels) the static layer may draw (about 450 MB RGB)."""


@dataclass(frozen=True)
class Walkways:
    """Pedestrian infrastructure of a net: sidewalks and crossings as (shape (N, 2), width [m]),
    walking areas as polygons (N, 2); plus every lane id of the net (for input checks)."""

    sidewalks: tuple[tuple[np.ndarray, float], ...]
    crossings: tuple[tuple[np.ndarray, float], ...]
    walking_areas: tuple[np.ndarray, ...]
    all_lane_ids: frozenset[str]


@functools.lru_cache(maxsize=8)
def read_walkways(net_path: str) -> Walkways:
    """Sidewalks, crossings and walking areas of a net file (cached)."""
    import sumolib

    net = sumolib.net.readNet(net_path, withInternal=True, withPedestrianConnections=True)
    sidewalks, crossings, areas, ids = [], [], [], set()
    for edge in net.getEdges(withInternal=True):
        function = edge.getFunction()
        for lane in edge.getLanes():
            ids.add(lane.getID())
            if lane.allows("passenger") or not lane.allows("pedestrian"):
                continue
            shape = np.asarray(lane.getShape(), dtype=float)[:, :2]
            if len(shape) < 2:
                continue
            if function == "walkingarea":
                areas.append(shape)
            elif function == "crossing":
                crossings.append((shape, float(lane.getWidth())))
            elif function == "":
                sidewalks.append((shape, float(lane.getWidth())))
    return Walkways(tuple(sidewalks), tuple(crossings), tuple(areas), frozenset(ids))


@dataclass(frozen=True, eq=False)
class StaticLayer:
    """A rasterised network.

    Attributes:
        image: RGB image of the whole network (plus a margin), north up.
        x0, y1: world coordinates [m] of the image's top-left corner.
        metres_per_px: scale of ``image`` [m/px].
    """

    image: Image.Image
    x0: float
    y1: float
    metres_per_px: float

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        """World points (..., 2) [m] -> continuous pixel coordinates (..., 2) of ``image``."""
        xy = np.asarray(xy, dtype=float)
        return np.stack([(xy[..., 0] - self.x0), (self.y1 - xy[..., 1])], axis=-1) / self.metres_per_px


def network_bounds(net: RoadNetwork) -> tuple[float, float, float, float]:
    """``(xmin, ymin, xmax, ymax)`` [m] of every lane (half widths included) and junction."""
    pts, pads = [], []
    for lane in list(net.lanes.values()) + list(net.internal_lanes.values()):
        pts.append(lane.shape)
        pads.append(np.full(len(lane.shape), lane.width / 2))
    for shape in net.junction_shapes.values():
        pts.append(shape)
        pads.append(np.zeros(len(shape)))
    walk = read_walkways(str(net.path))
    for shape, width in walk.sidewalks + walk.crossings:
        pts.append(shape)
        pads.append(np.full(len(shape), width / 2))
    p = np.concatenate(pts)
    pad = np.concatenate(pads)[:, None]
    lo, hi = (p - pad).min(axis=0), (p + pad).max(axis=0)
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


class _Canvas:
    """Pillow drawing in world metres on the supersampled canvas."""

    def __init__(self, image: Image.Image, x0: float, y1: float, mpp: float):
        self.draw = ImageDraw.Draw(image)
        self.x0, self.y1, self.mpp = x0, y1, mpp

    def px(self, xy: np.ndarray) -> list[tuple[float, float]]:
        xy = np.asarray(xy, dtype=float)
        return list(zip(((xy[:, 0] - self.x0) / self.mpp).tolist(), ((self.y1 - xy[:, 1]) / self.mpp).tolist()))

    def band(self, shape: np.ndarray, width_m: float, colour) -> None:
        """A polyline buffered to ``width_m`` (flat ends, round joints)."""
        width = max(1, int(round(width_m / self.mpp)))
        self.draw.line(self.px(shape), fill=colour, width=width, joint="curve")

    def polygon(self, shape: np.ndarray, colour, outline=None) -> None:
        self.draw.polygon(self.px(shape), fill=colour, outline=outline)


MARKING_KINDS = ("dashed", "centre", "edge")


def edge_markings(net: RoadNetwork, edge: str) -> list[tuple[np.ndarray, str]]:
    """Lane markings of a drivable edge: (polyline (N, 2) [m], kind) with kind ``dashed``
    (between its same-direction lanes), ``centre`` (left border towards an opposite edge) or
    ``edge`` (outer border: right of the rightmost lane, left of the leftmost one when the
    edge has no opposite)."""
    lanes = [net.lanes[i] for i in net.edge_lanes[edge]]
    out = [(offset_polyline(lanes[0].shape, -lanes[0].width / 2), "edge")]
    for k, lane in enumerate(lanes):
        left = offset_polyline(lane.shape, lane.width / 2)
        if k + 1 < len(lanes):
            out.append((left, "dashed"))
        else:
            out.append((left, "centre" if net.opposite.get(edge) else "edge"))
    return out


def _draw_markings(canvas: _Canvas, net: RoadNetwork) -> None:
    for edge in net.edge_lanes:
        for line, kind in edge_markings(net, edge):
            if kind == "dashed":
                for piece in dashes(line, DASH_ON_M, DASH_OFF_M):
                    canvas.band(piece, MARKING_WIDTH_M, palette.MARKING)
            elif kind == "centre":
                canvas.band(line, MARKING_WIDTH_M * 1.5, palette.CENTRE_LINE)
            else:
                canvas.band(line, MARKING_WIDTH_M, palette.MARKING)


def rasterise(net: RoadNetwork, metres_per_px: float, supersample: int = 2) -> StaticLayer:
    """Draw ``net`` at ``metres_per_px`` [m/px] (see the module docstring)."""
    if not (math.isfinite(metres_per_px) and metres_per_px > 0):
        raise ConfigError(f"metres_per_px must be finite and > 0, got {metres_per_px!r}")
    if int(supersample) != supersample or supersample < 1:
        raise ConfigError(f"supersample must be an int >= 1, got {supersample!r}")
    xmin, ymin, xmax, ymax = network_bounds(net)
    xmin, ymin = xmin - STATIC_MARGIN_M, ymin - STATIC_MARGIN_M
    xmax, ymax = xmax + STATIC_MARGIN_M, ymax + STATIC_MARGIN_M
    width = int(math.ceil((xmax - xmin) / metres_per_px))
    height = int(math.ceil((ymax - ymin) / metres_per_px))
    if width * height * supersample**2 > MAX_STATIC_PIXELS:
        raise ValueError(
            f"{net.path.name} at {metres_per_px} m/px (supersample {supersample}) needs a "
            f"{width * supersample}x{height * supersample} canvas; use a larger metres_per_px or supersample 1")
    mpp = metres_per_px / supersample
    image = Image.new("RGB", (width * supersample, height * supersample), palette.BACKGROUND)
    canvas = _Canvas(image, xmin, ymax, mpp)
    walk = read_walkways(str(net.path))
    for shape in net.junction_shapes.values():
        canvas.polygon(shape, palette.ROAD)
    for shape in walk.walking_areas:
        canvas.polygon(shape, palette.SIDEWALK)
    for shape, width_m in walk.sidewalks:
        canvas.band(shape, width_m + 0.3, palette.KERB)
    for shape, width_m in walk.sidewalks:
        canvas.band(shape, width_m, palette.SIDEWALK)
    for lane in net.internal_lanes.values():
        canvas.band(lane.shape, lane.width, palette.ROAD)
    for lane in net.lanes.values():
        canvas.band(lane.shape, lane.width, palette.ROAD)
    for shape, width_m in walk.crossings:
        canvas.band(shape, width_m, palette.ROAD)
        for piece in dashes(shape, ZEBRA_M, ZEBRA_M):
            canvas.band(piece, 0.8 * width_m, palette.MARKING)
    _draw_markings(canvas, net)
    if supersample > 1:
        image = image.reduce(supersample)
    return StaticLayer(image=image, x0=xmin, y1=ymax, metres_per_px=metres_per_px)


MAX_LAYERS_PER_NET = 4
_LAYERS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def static_layer(net: RoadNetwork, metres_per_px: float, supersample: int = 2) -> StaticLayer:
    """The static layer of ``net``, cached per network object, scale and supersampling
    (the scenario registry hands out one network object per town and process)."""
    per_net = _LAYERS.setdefault(net, {})
    key = (float(metres_per_px), int(supersample))
    if key not in per_net:
        if len(per_net) >= MAX_LAYERS_PER_NET:
            per_net.pop(next(iter(per_net)))
        per_net[key] = rasterise(net, metres_per_px, supersample)
    return per_net[key]
