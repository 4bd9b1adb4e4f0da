"""The sharable representation: occupancy grid M_t and road profile R_t (paper, "State Modeling").

M_t has shape (1, rows, cols): row i covers longitudinal offset [-back_m + i·cell_long_m, +cell_long_m)
from the ego (row 0 behind, last row ahead), column j covers lateral offset
[-cols/2·cell_lat_m + j·cell_lat_m, ...) (column 0 on the right). A cell is 1 when any vehicle or
pedestrian footprint covers it.

- ``deformed`` (default): offsets are curvilinear coordinates (arc length s, signed lateral d) along
  the centreline of the lane the ego follows along its route, through junctions; the grid is
  centred on that lane, not on the ego (the paper's deformed M_t).
- ``vehicle_centric``: offsets in the ego's own frame (x forward, y left), for the ablation.

R_t (``ROAD_FEATURES``, 10 entries, in the paper's order):
  e_l, e_r       1 if a drivable lane exists left / right of the ego's lane (0 inside a junction)
  a_l, a_c, a_r  1 if the left / current / right lane continues the route (links to the next route
                 edge, and in time for the goal lane: see ``RoadNetwork.route_lanes``; on the goal
                 edge: is the goal lane); 0 otherwise or if absent. When no lane next to the ego
                 continues the route and its own does not either, a_l (a_r) is 1 if the nearest
                 lane that does lies further left (right): see :func:`route_lane_features`
  l_g, l_y, l_r  one-hot state of the traffic light at the end of the current lane (all 0: none)
  d_s            distance to the stop line (end of the current lane) / lane length, in [0, 1]
  dv             speed / speed limit, clipped to [0, 2]

``road="metric"`` (:data:`ROAD_PROFILES`, not in the paper) appends two entries in metric units:
  d_stop         distance to the stop line [m] / 100 m, clipped to [0, 2] (2 inside a junction)
  v              speed [m/s] / 20 m/s, clipped to [0, 2]
The paper's d_s is relative to the lane's length, so a red light at d_s = 0.3 may be 9 m or 60 m
ahead: whether the ego can still stop is not in the paper's R_t. Measured on 72 k Town03 states
labelled by the lawful expert, a network on R_t alone predicts its behavior at red lights with
85 % accuracy, 92 % with ``d_stop`` (speed_down recall 67 % → 81 %).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from enum import IntEnum
from typing import TYPE_CHECKING

import numpy as np

from hbmp_bench.maps.roadnet import RoadNetwork
from hbmp_bench.planning.frame import Path
from hbmp_bench.planning.frame import round_corners as smooth_polyline
from hbmp_bench.errors import ConfigError

if TYPE_CHECKING:
    from hbmp_bench.sim.sumo import LightAhead

ROAD_FEATURES = ("e_l", "e_r", "a_l", "a_c", "a_r", "l_g", "l_y", "l_r", "d_s", "dv")
"""R_t's entries in order; :class:`Road` names their indices."""
ROAD_PROFILES = {"paper": ROAD_FEATURES, "metric": (*ROAD_FEATURES, "d_stop", "v")}
"""R_t's entries per ``ObservationConfig.road``: the paper's ten, or those and two in metric units."""
STOP_SCALE_M = 100.0
"""Scale of ``d_stop`` [m]."""
SPEED_SCALE_MPS = 20.0
"""Scale of ``v`` [m/s]."""
Road = IntEnum("Road", [(name.upper(), k) for k, name in enumerate(ROAD_PROFILES["metric"])])
"""Index of each R_t entry by name: ``road[Road.A_C]`` is a_c (no reading R_t by position)."""
LANE_WIDTH_M = 3.5
"""Lane width of the towns' networks [m] (``netconvert --default.lanewidth``), the scale of
lateral errors and of a lane offset in M_t's cells."""
CORNER_MIN_SPACING_M = 1.0
"""Least spacing of the vertices the centreline is rounded from [m]: a lane and the junction lane
it leads onto meet with a repeated vertex or one 0.2 m from a kink, which rounding alone turns into
a curvature of 2 1/m, and the planner's curve speed cap into a crawl across the stop line; merged,
a Town01/02 corner peaks at 0.26 1/m."""
GREEN, YELLOW, RED = "gGoOs", "yY", "rRu"


@dataclass(frozen=True)
class ObservationConfig:
    """Grid geometry of M_t.

    Attributes:
        kind: ``deformed`` or ``vehicle_centric``.
        rows / cols: grid size.
        cell_long_m / cell_lat_m: cell size along / across the lane [m].
        back_m: range behind the ego [m] (ahead = rows·cell_long_m − back_m).
        road: R_t's entries, a key of :data:`ROAD_PROFILES` (``paper``: the paper's ten).
    """

    kind: str = "deformed"
    rows: int = 64
    cols: int = 36
    cell_long_m: float = 1.0
    cell_lat_m: float = 0.5
    back_m: float = 16.0
    road: str = "paper"

    def __post_init__(self):
        if self.kind not in ("deformed", "vehicle_centric"):
            raise ConfigError(f"observation kind must be 'deformed' or 'vehicle_centric', got {self.kind!r}")
        if self.road not in ROAD_PROFILES:
            from hbmp_bench.errors import UnknownNameError

            raise UnknownNameError("road profile", self.road, tuple(ROAD_PROFILES))
        if self.rows <= 0 or self.cols <= 0 or self.cell_long_m <= 0 or self.cell_lat_m <= 0:
            raise ConfigError("grid sizes must be > 0")
        if not 0 <= self.back_m < self.rows * self.cell_long_m:
            raise ConfigError("back_m must lie inside the grid")

    @property
    def ahead_m(self) -> float:
        return self.rows * self.cell_long_m - self.back_m

    @property
    def half_width_m(self) -> float:
        return self.cols * self.cell_lat_m / 2

    @property
    def road_features(self) -> tuple[str, ...]:
        """R_t's entries in order."""
        return ROAD_PROFILES[self.road]


def observation_space(config: ObservationConfig):
    """The gymnasium space of the observation ``{"occupancy": M_t, "road": R_t}`` for ``config``."""
    from gymnasium import spaces

    return spaces.Dict(
        occupancy=spaces.Box(0.0, 1.0, (1, config.rows, config.cols), dtype=np.float32),
        road=spaces.Box(0.0, 2.0, (len(config.road_features),), dtype=np.float32),
    )


def route_lane_features(here: int, good: frozenset[int], has_left: bool, has_right: bool
                        ) -> tuple[bool, bool, bool, int]:
    """R_t's a_l, a_c, a_r and the signed offset to the nearest lane that continues the route.

    Lanes are numbered across the road with +1 one lane to the left. ``good`` are the lanes that
    continue the route (empty: none known). The paper defines a_l, a_c, a_r as the route direction
    of the three lanes; a road of four lanes whose route lane is two lanes away leaves all three 0,
    and a policy cannot tell which way to change (CARLA's Town04 motorways: the shipped ``il``
    stood still or passed its goal one lane off in 11 of 40 Straight episodes). Here a neighbour
    that leads towards the nearest route lane counts as continuing the route.

    Returns:
        (a_l, a_c, a_r, offset): offset in lanes (+ left) to the nearest route lane, 0 when the
        ego's lane is one or none is known.
    """
    offset = 0
    if here not in good and good:
        offset = min(good, key=lambda g: (abs(g - here), g)) - here
    a_l = has_left and (here + 1 in good or offset > 0)
    a_r = has_right and (here - 1 in good or offset < 0)
    return a_l, here in good, a_r, offset


def road_vector(config: ObservationConfig, paper_road: np.ndarray, stop_distance_m: float,
                speed_mps: float) -> np.ndarray:
    """R_t as ``config.road`` asks, float32: the paper's ten entries ``paper_road`` (10,), then for
    ``metric`` ``d_stop`` and ``v`` from the distance to the stop line [m] (inf: none ahead, e.g.
    inside a junction) and the speed [m/s]."""
    if config.road == "paper":
        return paper_road
    d_stop = _clip(stop_distance_m / STOP_SCALE_M, 0.0, 2.0) if math.isfinite(stop_distance_m) else 2.0
    v = _clip(speed_mps / SPEED_SCALE_MPS, 0.0, 2.0)
    return np.concatenate([paper_road, np.array([d_stop, v], dtype=np.float32)])


def _sample_boxes(xy: np.ndarray, yaw: np.ndarray, length: np.ndarray, width: np.ndarray, n_long: int = 10, n_lat: int = 4) -> np.ndarray:
    """Points (K·n_long·n_lat, 2) spread over K oriented boxes (corners included)."""
    u = np.linspace(-0.5, 0.5, n_long)
    v = np.linspace(-0.5, 0.5, n_lat)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    uu, vv = uu.ravel()[None], vv.ravel()[None]
    lon = uu * length[:, None]
    lat = vv * width[:, None]
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    return np.stack([xy[:, 0:1] + c * lon - s * lat, xy[:, 1:2] + s * lon + c * lat], axis=-1).reshape(-1, 2)


def followed_path(net: RoadNetwork, lane_id: str, next_edges: tuple[str, ...], back_m: float, ahead_m: float,
                  max_spacing: float | None = None, round_corners: int = 0, via: str = "",
                  into: tuple[frozenset[str], ...] = ()) -> Path:
    """The centreline the ego follows: ``lane_id`` extended straight back by ``back_m`` [m] and ahead
    by at least ``ahead_m`` [m] along the lanes that lead to the route's ``next_edges``, through
    junctions (the paper's "virtual lanes"); straight on past a dead end. Where a lane has several
    links onto the next edge, the one into the route's lanes there: ``into[k]``, the lanes of
    ``next_edges[k]`` to reach (``RoadNetwork.follow``; none given: the first link); ``via``: the
    junction lane to leave ``lane_id`` by, overriding that choice. ``max_spacing`` [m]
    densifies the polyline and ``round_corners`` passes of corner cutting round SUMO's coarse
    vertices (:func:`hbmp_bench.planning.round_corners`, after merging the vertices closer than
    ``CORNER_MIN_SPACING_M``), which the motion planner needs; the defaults keep SUMO's vertices
    (enough for M_t)."""
    shape = net.lane(lane_id).shape
    back = shape[0] - shape[1]
    back = back / max(np.hypot(*back), 1e-9)
    pieces = [shape[0] + back * back_m, shape]
    lane, beyond, k = lane_id, 0.0, 0
    while beyond < ahead_m:
        nxt = net.follow(lane, next_edges[k] if k < len(next_edges) else None, into[k] if k < len(into) else frozenset())
        if lane == lane_id and via and any(step == via for step, _ in net.lane_next.get(lane, ())):
            nxt = via
        if nxt is None:
            fwd = pieces[-1][-1] - pieces[-1][-2]
            pieces.append(pieces[-1][-1] + fwd / max(np.hypot(*fwd), 1e-9) * (ahead_m - beyond))
            break
        if nxt in net.lanes:
            k += 1
        pieces.append(net.lane(nxt).shape)
        beyond += net.lane(nxt).length
        lane = nxt
    xy = np.vstack([np.atleast_2d(p) for p in pieces])
    return Path(smooth_polyline(xy, round_corners, CORNER_MIN_SPACING_M) if round_corners else xy, max_spacing=max_spacing)


class ObservationBuilder:
    """Builds M_t and R_t for one network and grid config."""

    def __init__(self, net: RoadNetwork, config: ObservationConfig):
        self.net = net
        self.config = config
        self._path = functools.lru_cache(maxsize=256)(self._followed_path)

    def __getstate__(self) -> dict:
        """Without the path cache (an ``lru_cache`` over a bound method cannot be pickled)."""
        return {"net": self.net, "config": self.config}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["net"], state["config"])

    # ------------------------------------------------------------------ M_t
    def _followed_path(self, lane_id: str, next_edges: tuple[str, ...], into: tuple[frozenset[str], ...]) -> Path:
        return followed_path(self.net, lane_id, next_edges, self.config.back_m, self.config.ahead_m, into=into)

    def occupancy(self, ego_xy: np.ndarray, ego_yaw: float, lane_id: str, next_edges: tuple[str, ...],
                  xy: np.ndarray, yaw: np.ndarray, length: np.ndarray, width: np.ndarray,
                  into: tuple[frozenset[str], ...] = ()) -> np.ndarray:
        """M_t (1, rows, cols) float32 from the other actors (K,) arrays, deformed along the lane
        ``lane_id`` continued onto ``next_edges`` (into the lanes ``into``: :func:`followed_path`)."""
        path = self._path(lane_id, tuple(next_edges), tuple(into)) if self.config.kind == "deformed" and len(xy) else None
        return occupancy_grid(self.config, ego_xy, ego_yaw, path, xy, yaw, length, width)

    def occupancy_all(self, requests: list[tuple]) -> list[np.ndarray]:
        """:meth:`occupancy` of N vehicles, ``requests[n]`` its arguments in order: the same grids, the
        deformed ones rasterised in one compiled call (:func:`.occupancy_kernel.deformed_grids`; the sampling
        of each vehicle's nearby footprints computed for all at once)."""
        cfg = self.config
        if cfg.kind != "deformed" or len(requests) < 2:
            return [self.occupancy(*r) for r in requests]
        from hbmp_bench.envs.occupancy_kernel import deformed_grids  # numba loads on the first call

        counts = np.array([len(r[4]) for r in requests])
        out = [np.zeros((1, cfg.rows, cfg.cols), dtype=np.float32) for _ in requests]
        if not counts.any():
            return out
        ego_xy = np.array([r[0] for r in requests], dtype=float).reshape(-1, 2)
        xy = np.concatenate([r[4] for r in requests]).reshape(-1, 2)
        length = np.concatenate([r[6] for r in requests])
        width = np.concatenate([r[7] for r in requests])
        near = np.hypot(*(xy - np.repeat(ego_xy, counts, axis=0)).T) < cfg.rows * cfg.cell_long_m + 10.0
        bounds = np.concatenate([[0], np.cumsum(counts)])
        starts = bounds[:-1][counts > 0]  # reduceat over the vehicles with actors (the others lie between)
        has_actors = np.flatnonzero(counts > 0)
        near_count = np.zeros(len(requests), dtype=np.int64)
        near_count[has_actors] = np.add.reduceat(near.astype(np.int64), starts)
        drawn = np.flatnonzero(near_count > 0)
        if not len(drawn):
            return out
        longest = np.full(len(requests), -np.inf)
        widest = np.full(len(requests), -np.inf)
        longest[has_actors] = np.maximum.reduceat(np.where(near, length, -np.inf), starts)
        widest[has_actors] = np.maximum.reduceat(np.where(near, width, -np.inf), starts)
        step = min(cfg.cell_long_m, cfg.cell_lat_m)  # as _footprint_sampling, per vehicle
        n_long = np.maximum(10, np.ceil(longest[drawn].astype(float) / step).astype(np.int64) + 1)
        n_lat = np.maximum(4, np.ceil(widest[drawn].astype(float) / step).astype(np.int64) + 1)
        paths = [self._path(requests[n][2], tuple(requests[n][3]),
                            tuple(requests[n][8]) if len(requests[n]) > 8 else ()).segment_arrays() for n in drawn]
        keep = near  # (of the drawn vehicles only)
        yaw = np.concatenate([r[5] for r in requests])
        actor_start = np.concatenate([[0], np.cumsum(near_count[drawn])])
        seg_start = np.concatenate([[0], np.cumsum([len(p[1]) for p in paths])])
        arrays = [np.concatenate([p[k] for p in paths]) for k in range(10)]
        grids = deformed_grids(ego_xy[drawn], actor_start, xy[keep, 0], xy[keep, 1], yaw[keep].astype(float),
                               length[keep].astype(float), width[keep].astype(float), n_long, n_lat,
                               seg_start, *arrays, cfg.rows, cfg.cols, float(cfg.cell_long_m), float(cfg.cell_lat_m),
                               float(cfg.back_m), float(cfg.ahead_m), float(cfg.half_width_m))
        for k, n in enumerate(drawn.tolist()):
            out[n] = grids[k]
        return out


def _footprint_sampling(cfg: ObservationConfig, ego_xy: np.ndarray, xy: np.ndarray, length: np.ndarray,
                        width: np.ndarray) -> tuple[np.ndarray, int, int] | None:
    """The actors M_t samples (a (K,) mask) and the sample points along / across each footprint, or None
    when none is near: samples no farther apart than a cell along both box axes, so no covered cell is
    skipped."""
    if len(xy) == 0:
        return None
    near = np.hypot(*(xy - ego_xy).T) < cfg.rows * cfg.cell_long_m + 10.0
    if not near.any():
        return None
    step = min(cfg.cell_long_m, cfg.cell_lat_m)
    n_long = max(10, int(np.ceil(float(length[near].max()) / step)) + 1)
    n_lat = max(4, int(np.ceil(float(width[near].max()) / step)) + 1)
    return near, n_long, n_lat


def occupancy_grid(cfg: ObservationConfig, ego_xy: np.ndarray, ego_yaw: float, path: Path | None,
                   xy: np.ndarray, yaw: np.ndarray, length: np.ndarray, width: np.ndarray) -> np.ndarray:
    """M_t (1, rows, cols) float32 from geometry alone (any simulator): the ego centre ``ego_xy`` (2,) [m]
    and heading ``ego_yaw`` [rad], the followed-lane centreline ``path`` (needed for ``deformed``,
    ignored for ``vehicle_centric``), and the other actors' footprints: centres ``xy`` (K, 2) [m],
    headings ``yaw`` (K,) [rad], ``length`` / ``width`` (K,) [m]. Right-handed frame (y left of x).

    The deformed grid is rasterised compiled (:func:`.occupancy_kernel.deformed_grid`, the same cells as
    :func:`occupancy_grid_reference`, its numpy form)."""
    if cfg.kind != "deformed":
        return occupancy_grid_reference(cfg, ego_xy, ego_yaw, path, xy, yaw, length, width)
    sampling = _footprint_sampling(cfg, ego_xy, xy, length, width)
    if sampling is None:
        return np.zeros((1, cfg.rows, cfg.cols), dtype=np.float32)
    if path is None:
        raise ValueError("a deformed M_t needs the followed lane's centreline (path)")
    from hbmp_bench.envs.occupancy_kernel import deformed_grid  # numba loads on the first call

    near, n_long, n_lat = sampling
    return deformed_grid(float(ego_xy[0]), float(ego_xy[1]), xy[near, 0], xy[near, 1], yaw[near].astype(float),
                         length[near].astype(float), width[near].astype(float), n_long, n_lat, *path.segment_arrays(),
                         cfg.rows, cfg.cols, float(cfg.cell_long_m), float(cfg.cell_lat_m), float(cfg.back_m),
                         float(cfg.ahead_m), float(cfg.half_width_m))


def occupancy_grid_reference(cfg: ObservationConfig, ego_xy: np.ndarray, ego_yaw: float, path: Path | None,
                             xy: np.ndarray, yaw: np.ndarray, length: np.ndarray, width: np.ndarray) -> np.ndarray:
    """:func:`occupancy_grid` in numpy (the vehicle-centric grid's only form; the deformed one's reference)."""
    grid = np.zeros((1, cfg.rows, cfg.cols), dtype=np.float32)
    sampling = _footprint_sampling(cfg, ego_xy, xy, length, width)
    if sampling is None:
        return grid
    near, n_long, n_lat = sampling
    points = _sample_boxes(xy[near], yaw[near], length[near], width[near], n_long=n_long, n_lat=n_lat)
    if cfg.kind == "deformed":
        if path is None:
            raise ValueError("a deformed M_t needs the followed lane's centreline (path)")
        s_ego, _ = path.frenet(ego_xy)
        s, lat = path.frenet(points, hint_s=s_ego, window=(cfg.back_m + 10.0, cfg.ahead_m + 10.0))
        lon = s - s_ego
    else:
        rel = points - ego_xy
        c, s_ = np.cos(ego_yaw), np.sin(ego_yaw)
        lon, lat = rel[:, 0] * c + rel[:, 1] * s_, -rel[:, 0] * s_ + rel[:, 1] * c
    i = np.floor((lon + cfg.back_m) / cfg.cell_long_m).astype(int)
    j = np.floor((lat + cfg.half_width_m) / cfg.cell_lat_m).astype(int)
    ok = (i >= 0) & (i < cfg.rows) & (j >= 0) & (j < cfg.cols)
    grid[0, i[ok], j[ok]] = 1.0
    return grid


def road_profile(net: RoadNetwork, lane_id: str, lane_pos: float, route: tuple[str, ...], route_index: int,
                 goal_lane: str, speed: float, light: LightAhead | None,
                 goal_pos: float | None = None) -> tuple[np.ndarray, dict]:
    """R_t (10,) float32 and the quantities it was made of (metres, m/s) for privileged users.

    Args:
        lane_id / lane_pos: the ego's lane and front-bumper position on it [m].
        route / route_index: the episode route and the index of the ego's edge (or of the edge
            before the junction it is crossing).
        goal_lane / goal_pos: the lane the goal lies on and its position on it [m] (None: no fixed
            goal point, e.g. circulating traffic).
        speed: ego speed [m/s].
        light: the next traffic light on the route (its ``distance`` [m] to the stop line and
            ``state`` char are read) or None.
    """
    r = np.zeros(len(ROAD_FEATURES), dtype=np.float32)
    lane = net.lane(lane_id)
    in_junction = lane_id not in net.lanes
    scene = {
        "speed_mps": float(speed),
        "speed_limit_mps": float(lane.speed),
        "in_junction": in_junction,
        "route_lane_offset": 0,
        "stop_distance_m": float("inf"),
        "lane_pos_m": 0.0,
        "light": "",
    }
    scene["turn_ahead"] = ""
    if not in_junction:
        next_edge = route[route_index + 1] if route_index + 1 < len(route) else None
        if next_edge is not None and net.links(lane.edge, next_edge):
            scene["turn_ahead"] = net.direction(lane.edge, next_edge)
        good = net.route_lanes(route, goal_lane, goal_pos)[route_index]
        ids = net.edge_lanes[lane.edge]
        here = ids.index(lane_id)
        left = ids[here + 1] if here + 1 < len(ids) else None
        right = ids[here - 1] if here > 0 else None
        r[0], r[1] = left is not None, right is not None
        good_here = frozenset(ids.index(g) for g in good if g in ids)
        r[2], r[3], r[4], scene["route_lane_offset"] = route_lane_features(here, good_here, r[0] > 0, r[1] > 0)
        remaining = max(lane.length - lane_pos, 0.0)
        r[8] = _clip(remaining / max(lane.length, 1e-6), 0.0, 1.0)
        scene["stop_distance_m"] = remaining
        scene["lane_pos_m"] = float(lane_pos)
        if light is not None and light.distance <= remaining + 1.0:
            state = light.state
            r[5], r[6], r[7] = state in GREEN, state in YELLOW, state in RED
            scene["light"] = state
            scene["stop_distance_m"] = float(light.distance)
    else:
        r[3] = 1.0
        if light is not None:  # privileged only: the next light beyond the junction (R_t: none)
            scene["light"] = light.state
            scene["stop_distance_m"] = float(light.distance)
    r[9] = _clip(speed / max(lane.speed, 1e-6), 0.0, 2.0)
    return r, scene


def _clip(x: float, lo: float, hi: float) -> float:
    """``np.clip`` of one number (NaN stays NaN), without the array machinery (~5 µs a call, 4 per R_t)."""
    return x if x != x else min(max(x, lo), hi)
