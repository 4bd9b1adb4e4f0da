"""Headless top-down renderer: a :class:`SceneView` -> an RGB frame (H, W, 3) uint8.

The static layer (roads, sidewalks, crossings, markings) is rasterised once per network
and scale (:mod:`.static`); each frame resamples it with one affine transform (crop and
rotation in a single bilinear pass over the output pixels only) and draws the dynamic
items on top with Pillow, in this order: route band (translucent), stop bars, goal,
planner samples (thin; infeasible ones red) and the chosen one (thick), vehicles (boxes,
ego highlighted with a heading triangle), pedestrians (dots), caption.

Views (:class:`RenderConfig`):

* ``follow`` (default): ego-centred at ``metres_per_px``; heading-up by default (the ego
  points to the top of the image, its right-hand side to the image's right), north-up with
  ``heading_up=False``.
* ``map``: the whole network fitted into the image, north up; ``metres_per_px`` is ignored.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from hbmp_bench.errors import ConfigError
from hbmp_bench.maps.roadnet import RoadNetwork
from hbmp_bench.render import palette
from hbmp_bench.render.geometry import box_corners
from hbmp_bench.render.scene import SceneView
from hbmp_bench.render.static import StaticLayer, network_bounds, read_walkways, static_layer

VIEWS = ("follow", "map")
STOP_BAR_M = 0.8
"""Thickness of a traffic-light stop bar [m]."""
GOAL_RADIUS_M = 1.5
PEDESTRIAN_RADIUS_M = 0.5
ROUTE_CACHE_SIZE = 8


@dataclass(frozen=True)
class RenderConfig:
    """Frame size and view.

    Attributes:
        width, height: frame size [px].
        metres_per_px: scale of the ``follow`` view [m/px] (0.25: a 400 px frame shows 100 m).
        view: ``follow`` (ego-centred) or ``map`` (whole network, north up).
        heading_up: in ``follow``, rotate so the ego points up (else north up).
        supersample: the static layer is drawn this many times finer and box-filtered down
            (anti-aliased roads and markings); 1 is faster to build and lighter in memory.
        show_route, show_plan: draw the route band / the planner samples when present.
    """

    width: int = 400
    height: int = 400
    metres_per_px: float = 0.25
    view: str = "follow"
    heading_up: bool = True
    supersample: int = 2
    show_route: bool = True
    show_plan: bool = True

    def __post_init__(self):
        for name in ("width", "height", "supersample"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
                raise ConfigError(f"RenderConfig.{name} must be an int >= 1, got {value!r}")
        if self.width < 16 or self.height < 16:
            raise ConfigError(f"RenderConfig frame must be at least 16x16 px, got {self.width}x{self.height}")
        if not (math.isfinite(self.metres_per_px) and self.metres_per_px > 0):
            raise ConfigError(f"RenderConfig.metres_per_px must be finite and > 0, got {self.metres_per_px!r}")
        if self.view not in VIEWS:
            raise ConfigError(f"RenderConfig.view must be one of {VIEWS}, got {self.view!r}")


@dataclass(frozen=True)
class ViewTransform:
    """World -> frame pixels: the world point ``centre`` lands at the frame centre, the
    direction ``up_yaw`` [rad] points to the top, at ``metres_per_px`` [m/px].

    Pixel coordinates are continuous (pixel ``(c, r)`` covers ``[c, c+1) x [r, r+1)``).
    """

    centre: tuple[float, float]
    up_yaw: float
    metres_per_px: float
    width: int
    height: int

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        """World points (..., 2) [m] -> pixel coordinates (..., 2) ``(column, row)``."""
        xy = np.asarray(xy, dtype=float)
        c, s = math.cos(self.up_yaw), math.sin(self.up_yaw)
        dx, dy = xy[..., 0] - self.centre[0], xy[..., 1] - self.centre[1]
        right = (dx * s - dy * c) / self.metres_per_px
        ahead = (dx * c + dy * s) / self.metres_per_px
        return np.stack([0.5 * self.width + right, 0.5 * self.height - ahead], axis=-1)

    def affine_from(self, layer: StaticLayer) -> tuple[float, ...]:
        """Pillow ``AFFINE`` data mapping frame pixels to ``layer.image`` pixels."""
        c, s = math.cos(self.up_yaw), math.sin(self.up_yaw)
        k = self.metres_per_px / layer.metres_per_px
        # world = centre + (col - W/2) * mpp * (s, -c) + (H/2 - row) * mpp * (c, s)
        cx = (self.centre[0] - layer.x0) / layer.metres_per_px
        cy = (layer.y1 - self.centre[1]) / layer.metres_per_px
        hw, hh = 0.5 * self.width, 0.5 * self.height
        a, b = k * s, -k * c
        d, e = k * c, k * s
        return (a, b, cx - a * hw - b * hh, d, e, cy - d * hw - e * hh)


def _poly(points: np.ndarray) -> list[tuple[float, float]]:
    return [tuple(p) for p in np.asarray(points, dtype=float).tolist()]


class TopDownRenderer:
    """Renders :class:`SceneView` s of one network.

    Args:
        net: the road network the scenes live on.
        config: frame size and view.
    """

    def __init__(self, net: RoadNetwork, config: RenderConfig = RenderConfig()):
        self.net = net
        self.config = config
        self._walkways = read_walkways(str(net.path))
        if config.view == "map":
            xmin, ymin, xmax, ymax = network_bounds(net)
            self._map_centre = (0.5 * (xmin + xmax), 0.5 * (ymin + ymax))
            self.metres_per_px = 1.05 * max((xmax - xmin) / config.width, (ymax - ymin) / config.height)
        else:
            self.metres_per_px = config.metres_per_px
        self._static: StaticLayer | None = None
        self._stop_bars: dict[str, np.ndarray | None] = {}
        self._routes: OrderedDict[tuple[str, ...], list[tuple[np.ndarray, float]]] = OrderedDict()
        self._font = ImageFont.load_default(size=max(10, config.height // 30))

    @property
    def static(self) -> StaticLayer:
        """The network's static layer at this renderer's scale (built on first use)."""
        if self._static is None:
            self._static = static_layer(self.net, self.metres_per_px, self.config.supersample)
        return self._static

    def transform(self, view: SceneView) -> ViewTransform:
        """The world -> pixel transform of a frame of ``view``."""
        cfg = self.config
        if cfg.view == "map":
            centre, up = self._map_centre, math.pi / 2
        else:
            centre = (float(view.ego_xy[0]), float(view.ego_xy[1]))
            up = view.ego_yaw if cfg.heading_up else math.pi / 2
        return ViewTransform(centre, up, self.metres_per_px, cfg.width, cfg.height)

    # ------------------------------------------------------------------ frame
    def frame(self, view: SceneView) -> np.ndarray:
        """The frame of ``view``: (height, width, 3) uint8 RGB."""
        cfg = self.config
        tf = self.transform(view)
        layer = self.static
        image = layer.image.transform((cfg.width, cfg.height), Image.Transform.AFFINE, tf.affine_from(layer),
                                      resample=Image.Resampling.BILINEAR, fillcolor=palette.BACKGROUND)
        draw = ImageDraw.Draw(image)
        if cfg.show_route and view.route_edges:
            self._draw_route(image, tf, view.route_edges)
        self._draw_lights(draw, tf, view.light_states)
        if view.goal_xy is not None:
            self._dot(draw, tf, view.goal_xy, GOAL_RADIUS_M, 4.0, palette.GOAL, outline=palette.EGO_OUTLINE)
        if cfg.show_plan and view.plan_trajectories is not None:
            self._draw_plan(draw, tf, view)
        self._draw_actors(draw, tf, view)
        self._draw_ego(draw, tf, view)
        if view.caption:
            self._draw_caption(image, view.caption)
        return np.array(image, dtype=np.uint8)

    __call__ = frame

    # ------------------------------------------------------------- layers
    def route_polylines(self, route: tuple[str, ...]) -> list[tuple[np.ndarray, float]]:
        """(shape (N, 2) [m], width [m]) of every lane of the route's edges and of the junction
        lanes linking consecutive edges (cached per route)."""
        if route in self._routes:
            self._routes.move_to_end(route)
            return self._routes[route]
        net = self.net
        out = []
        for k, edge in enumerate(route):
            if edge not in net.edge_lanes:
                raise ValueError(f"route edge {edge!r} is not a drivable edge of {net.path.name}")
            out.extend((net.lanes[i].shape, net.lanes[i].width) for i in net.edge_lanes[edge])
            if k + 1 < len(route):
                for link in net.links(edge, route[k + 1]):
                    lane = link.via
                    while lane in net.internal_lanes:
                        out.append((net.internal_lanes[lane].shape, net.internal_lanes[lane].width))
                        lane = net.follow(lane, route[k + 1])
        self._routes[route] = out
        if len(self._routes) > ROUTE_CACHE_SIZE:
            self._routes.popitem(last=False)
        return out

    def _draw_route(self, image: Image.Image, tf: ViewTransform, route: tuple[str, ...]) -> None:
        mask = Image.new("L", image.size, 0)
        draw = ImageDraw.Draw(mask)
        alpha = int(round(255 * palette.ROUTE_ALPHA))
        for shape, width in self.route_polylines(route):
            draw.line(_poly(tf.to_px(shape)), fill=alpha, width=max(2, int(round(width / tf.metres_per_px))),
                      joint="curve")
        image.paste(palette.ROUTE, (0, 0, *image.size), mask)

    def stop_bar(self, lane_id: str) -> np.ndarray | None:
        """Corners (4, 2) [m] of the stop bar across the end of a drivable lane (cached); None for
        lanes of the net that are not drivable normal lanes (crossings, junction lanes).
        ValueError for an id the net does not have."""
        if lane_id not in self._stop_bars:
            lane = self.net.lanes.get(lane_id)
            if lane is None:
                if lane_id not in self._walkways.all_lane_ids:
                    raise ValueError(f"light_states lane {lane_id!r} is not a lane of {self.net.path.name}")
                self._stop_bars[lane_id] = None
            else:
                end, before = lane.shape[-1], lane.shape[-2]
                direction = (end - before) / max(float(np.hypot(*(end - before))), 1e-9)
                centre = end - 0.5 * STOP_BAR_M * direction
                yaw = math.atan2(direction[1], direction[0])
                self._stop_bars[lane_id] = box_corners(centre[None], [yaw], [STOP_BAR_M], [lane.width])[0]
        return self._stop_bars[lane_id]

    def _draw_lights(self, draw: ImageDraw.ImageDraw, tf: ViewTransform, lights: dict[str, str]) -> None:
        bars = [(self.stop_bar(lane_id), state) for lane_id, state in lights.items()]
        bars = [(corners, state) for corners, state in bars if corners is not None]
        if not bars:
            return
        px = tf.to_px(np.stack([corners for corners, _ in bars]))  # (L, 4, 2)
        visible = ((px[..., 0].max(axis=1) >= 0) & (px[..., 0].min(axis=1) < tf.width)
                   & (px[..., 1].max(axis=1) >= 0) & (px[..., 1].min(axis=1) < tf.height))
        for k in np.flatnonzero(visible):
            draw.polygon(_poly(px[k]), fill=palette.SIGNAL[bars[k][1]])

    def _dot(self, draw, tf: ViewTransform, xy, radius_m: float, min_px: float, colour, outline=None) -> None:
        c, r = tf.to_px(xy)
        rad = max(radius_m / tf.metres_per_px, min_px)
        draw.ellipse((c - rad, r - rad, c + rad, r + rad), fill=colour, outline=outline)

    def _draw_plan(self, draw: ImageDraw.ImageDraw, tf: ViewTransform, view: SceneView) -> None:
        px = tf.to_px(view.plan_trajectories)
        feasible = view.plan_feasible
        for i, line in enumerate(px):
            if i == view.plan_chosen or len(line) < 2:
                continue
            ok = True if feasible is None else bool(feasible[i])
            draw.line(_poly(line), fill=palette.PLAN_FEASIBLE if ok else palette.PLAN_INFEASIBLE, width=1)
        if view.plan_chosen is not None and len(px[view.plan_chosen]) >= 2:
            width = max(3, int(round(0.5 / tf.metres_per_px)))
            draw.line(_poly(px[view.plan_chosen]), fill=palette.PLAN_CHOSEN, width=width, joint="curve")

    def _draw_actors(self, draw: ImageDraw.ImageDraw, tf: ViewTransform, view: SceneView) -> None:
        if view.n_actors == 0:
            return
        ped = view.actors_is_pedestrian
        mpp = tf.metres_per_px
        vehicles = ~ped
        length = np.maximum(view.actors_length[vehicles], 3 * mpp)
        width = np.maximum(view.actors_width[vehicles], 2 * mpp)
        corners = box_corners(view.actors_xy[vehicles], view.actors_yaw[vehicles], length, width)
        for box in tf.to_px(corners):
            draw.polygon(_poly(box), fill=palette.VEHICLE, outline=palette.VEHICLE_OUTLINE)
        for xy in view.actors_xy[ped]:
            self._dot(draw, tf, xy, PEDESTRIAN_RADIUS_M, 2.5, palette.PEDESTRIAN)

    def _draw_ego(self, draw: ImageDraw.ImageDraw, tf: ViewTransform, view: SceneView) -> None:
        mpp = tf.metres_per_px
        length, width = max(view.ego_length, 4 * mpp), max(view.ego_width, 3 * mpp)
        box = box_corners(view.ego_xy[None], [view.ego_yaw], [length], [width])[0]
        draw.polygon(_poly(tf.to_px(box)), fill=palette.EGO, outline=palette.EGO_OUTLINE)
        c, s = math.cos(view.ego_yaw), math.sin(view.ego_yaw)
        fwd, left = np.array([c, s]), np.array([-s, c])
        tip = view.ego_xy + 0.45 * length * fwd
        base = view.ego_xy + 0.12 * length * fwd
        triangle = np.stack([tip, base + 0.3 * width * left, base - 0.3 * width * left])
        draw.polygon(_poly(tf.to_px(triangle)), fill=palette.EGO_OUTLINE)

    def _draw_caption(self, image: Image.Image, text: str) -> None:
        draw = ImageDraw.Draw(image, "RGBA")
        left, top, right, bottom = draw.textbbox((4, 3), text, font=self._font)
        back = (*palette.CAPTION_BACK, int(round(255 * palette.CAPTION_ALPHA)))
        draw.rectangle((0, 0, image.size[0], bottom + 4), fill=back)
        draw.text((4, 3), text, font=self._font, fill=palette.CAPTION_TEXT)
