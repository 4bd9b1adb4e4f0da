"""The sharable representation read off a highway-env scene, and the behaviors mapped onto its actions.

highway-env draws its world with the screen's y axis pointing down: a lane to the *right* of the
direction of travel has a *larger* y and a larger lane id (``LANE_RIGHT`` is ``id + 1``), and lane
``lateral`` coordinates are positive to the right. This package's frame is right-handed (y to the
left, as in SUMO), so every highway-env position is mirrored, ``(x, y) -> (x, -y)`` and headings
``psi -> -psi``, before M_t is built; "left" then means ``id - 1`` in highway-env.

M_t comes from :func:`hbmp_bench.envs.observation.occupancy_grid`, the same code the SUMO env uses;
only the followed-lane centreline is built here, from the lane geometry of highway-env's road
network (``lane.position``) along the ego's planned route. R_t has the SUMO semantics
(:mod:`hbmp_bench.envs.observation`), with these readings of highway-env's network:

- e_l / e_r: the neighbouring lane of the ego's road exists and highway-env lets the ego change
  into it (``is_reachable_from``: not ``forbidden``, beside the ego); 0 in a junction.
- a_l / a_c / a_r: the lane continues the route: its end is within 1 m of the best connection of
  the ego's road to the next road of the route (``ego.route``; without a route the only next road,
  or highway-env's own choice). A lane that ends in a merge or leads past an exit does not; with
  no next road (end of the network) every lane does. In a junction a_c = 1.
- l_g / l_y / l_r: always 0 (highway-env has no traffic lights).
- d_s: distance from the ego's front bumper to the end of its lane / lane length; 0 in a junction.
- dv: speed / the scene's speed limit, clipped to [0, 2].
"""

from __future__ import annotations

import numpy as np

try:
    from highway_env.road.lane import SineLane, StraightLane
except ModuleNotFoundError as exc:
    if (exc.name or "").partition(".")[0] != "highway_env":
        raise
    raise ModuleNotFoundError("the highway-env transfer envs need highway-env, an optional extra: "
                              "pip install 'hbmp-bench[highway-env]'", name=exc.name) from exc

from hbmp_bench.envs.observation import (ROAD_FEATURES, ObservationConfig, occupancy_grid, road_vector,
                                         route_lane_features)
from hbmp_bench.planning.behaviors import BEHAVIORS, Behavior
from hbmp_bench.planning.frame import Path
from hbmp_bench.transfer.scenes import TransferScene

META_ACTIONS = ("LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER")
"""highway-env's DiscreteMetaAction (all actions), in its index order."""
BEHAVIOR_TO_META = (3, 4, 0, 2, 1)
"""Meta-action index of each behavior: speed_up -> FASTER, speed_down -> SLOWER, change_left ->
LANE_LEFT, change_right -> LANE_RIGHT, keep -> IDLE."""
META_TO_BEHAVIOR = tuple(BEHAVIOR_TO_META.index(m) for m in range(len(META_ACTIONS)))
CONTINUES_TOL_M = 1.0
"""A lane continues the route when its end lies within this distance [m] of the best connection."""
_R = {name: k for k, name in enumerate(ROAD_FEATURES)}

LaneIndex = tuple[str, str, int]


def to_meta_action(behavior: int) -> int:
    """DiscreteMetaAction index for a behavior index in [0, 5)."""
    if not 0 <= int(behavior) < len(BEHAVIORS):
        raise ValueError(f"behavior must be in [0, {len(BEHAVIORS)}), got {behavior!r}")
    return BEHAVIOR_TO_META[int(behavior)]


def to_behavior(meta_action: int) -> int:
    """Behavior index for a DiscreteMetaAction index in [0, 5)."""
    if not 0 <= int(meta_action) < len(META_ACTIONS):
        raise ValueError(f"meta action must be in [0, {len(META_ACTIONS)}), got {meta_action!r}")
    return META_TO_BEHAVIOR[int(meta_action)]


def mirror(xy: np.ndarray) -> np.ndarray:
    """highway-env positions (..., 2) [m] in this package's right-handed frame (y flipped)."""
    out = np.array(xy, dtype=float)
    out[..., 1] *= -1.0
    return out


class HighwayAdapter:
    """M_t, R_t, the ``scene`` dict and the action mask for the ego of one highway-env
    episode. Build a new one for every episode (highway-env rebuilds its road on reset).

    Args:
        road: the highway-env ``Road`` (network, vehicles, objects).
        scene: the scene spec (speed limit, junction roads, goal).
        config: the M_t grid.
        sample_spacing_m: spacing of the points sampled on curved lanes [m].
    """

    def __init__(self, road, scene: TransferScene, config: ObservationConfig, sample_spacing_m: float = 1.0):
        self.road = road
        self.network = road.network
        self.scene = scene
        self.config = config
        self.sample_spacing_m = sample_spacing_m
        self._polylines: dict[LaneIndex, tuple[np.ndarray, np.ndarray]] = {}
        self._good: dict[tuple, frozenset[int]] = {}
        if scene.goal_road is not None:
            goal_lane = self.network.get_lane((*scene.goal_road, 0))
            self.goal_xy = mirror(goal_lane.position(scene.goal_s_m, 0.0))
        else:
            self.goal_xy = None

    # ------------------------------------------------------------ network
    def lane_polyline(self, index: LaneIndex) -> tuple[np.ndarray, np.ndarray]:
        """Centreline of a lane: lane coordinates ``s`` (N,) [m] and mirrored points (N, 2) [m]
        (the two ends for a straight lane, every ``sample_spacing_m`` otherwise)."""
        if index not in self._polylines:
            lane = self.network.get_lane(index)
            if isinstance(lane, StraightLane) and not isinstance(lane, SineLane):
                s = np.array([0.0, float(lane.length)])
            else:
                n = max(int(np.ceil(lane.length / self.sample_spacing_m)), 1)
                s = np.linspace(0.0, float(lane.length), n + 1)
            xy = mirror(np.array([lane.position(float(si), 0.0) for si in s]))
            self._polylines[index] = (s, xy)
        return self._polylines[index]

    def next_road(self, road: tuple[str, str], route) -> tuple[str, str] | None:
        """The road after ``road``: the route's, else the only one, else highway-env's choice."""
        outs = self.network.graph.get(road[1], {})
        if not outs:
            return None
        for entry in route or ():
            if entry[0] == road[1] and entry[1] in outs:
                return road[1], entry[1]
        if len(outs) == 1:
            return road[1], next(iter(outs))
        lane = self.network.get_lane((*road, 0))
        nxt = self.network.next_lane((*road, 0), route=None, position=lane.position(lane.length, 0.0))
        return nxt[0], nxt[1]

    def next_lane(self, index: LaneIndex, route) -> LaneIndex | None:
        """The lane highway-env's controller follows after ``index`` towards the next road."""
        nxt = self.next_road(index[:2], route)
        if nxt is None:
            return None
        lane = self.network.get_lane(index)
        next_id, _ = self.network.next_lane_given_next_road(
            index[0], index[1], index[2], nxt[1], None, lane.position(lane.length, 0.0))
        return (nxt[0], nxt[1], int(next_id))

    def good_lanes(self, road: tuple[str, str], route) -> frozenset[int]:
        """Lane ids of ``road`` that continue the route (see the module docstring)."""
        nxt = self.next_road(road, route)
        key = (road, nxt)
        if key not in self._good:
            lanes = self.network.graph[road[0]][road[1]]
            if nxt is None:
                good = frozenset(range(len(lanes)))
            else:
                starts = np.array([l.position(0.0, 0.0) for l in self.network.graph[nxt[0]][nxt[1]]])
                gaps = np.array([np.min(np.hypot(*(starts - l.position(l.length, 0.0)).T)) for l in lanes])
                good = frozenset(int(i) for i in np.flatnonzero(gaps <= gaps.min() + CONTINUES_TOL_M))
            self._good[key] = good
        return self._good[key]

    def in_junction(self, index: LaneIndex) -> bool:
        return index[0] in self.scene.junction_from_nodes

    def followed_path(self, index: LaneIndex, s_ego: float, route) -> Path:
        """Mirrored centreline of the ego's lane from ``back_m`` behind to ``ahead_m`` ahead of
        ``s_ego`` [m] along the lanes the route leads to (straight on past the end)."""
        cfg = self.config
        s, xy = self.lane_polyline(index)
        lo = max(int(np.searchsorted(s, s_ego - cfg.back_m - 5.0)) - 1, 0)
        hi = min(int(np.searchsorted(s, s_ego + cfg.ahead_m + 5.0)) + 1, len(s))
        pieces = [xy[lo:hi]]
        beyond = float(s[-1] - s_ego)
        lane = index
        while beyond < cfg.ahead_m + 5.0:
            lane = self.next_lane(lane, route)
            if lane is None:
                break
            s_next, xy_next = self.lane_polyline(lane)
            pieces.append(xy_next)
            beyond += float(s_next[-1])
        return Path(np.vstack(pieces), max_spacing=None)

    # ------------------------------------------------------------ observe
    def neighbours(self, ego) -> tuple[LaneIndex | None, LaneIndex | None]:
        """Lanes left and right of the ego's lane that it may change into (None if not)."""
        fr, to, i = ego.lane_index
        n = len(self.network.graph[fr][to])
        out = []
        for j in (i - 1, i + 1):
            ok = 0 <= j < n and self.network.get_lane((fr, to, j)).is_reachable_from(ego.position)
            out.append((fr, to, j) if ok else None)
        return out[0], out[1]

    def action_mask(self, ego) -> np.ndarray:
        """(5,) int8: 1 where a behavior is feasible for R_t (lane changes need the target lane)."""
        mask = np.ones(len(BEHAVIORS), dtype=np.int8)
        if self.in_junction(ego.lane_index):
            mask[Behavior.CHANGE_LEFT] = mask[Behavior.CHANGE_RIGHT] = 0
        else:
            left, right = self.neighbours(ego)
            mask[Behavior.CHANGE_LEFT], mask[Behavior.CHANGE_RIGHT] = left is not None, right is not None
        return mask

    def road_profile(self, ego) -> tuple[np.ndarray, dict]:
        """R_t (10,) float32 and the ``scene`` dict (metres, m/s): R_t's quantities and the goal
        distance, the non-privileged fields of :class:`~hbmp_bench.envs.scene.Scene`."""
        r = np.zeros(len(ROAD_FEATURES), dtype=np.float32)
        index = ego.lane_index
        lane = self.network.get_lane(index)
        speed = float(ego.speed)
        limit = self.scene.speed_limit_mps
        scene = {
            "speed_mps": speed,
            "speed_limit_mps": limit,
            "in_junction": self.in_junction(index),
            "route_lane_offset": 0,
            "stop_distance_m": float("inf"),
            "light": "",
        }
        if scene["in_junction"]:
            r[_R["a_c"]] = 1.0
        else:
            route = getattr(ego, "route", None)
            good = self.good_lanes(index[:2], route)
            here, n = index[2], len(self.network.graph[index[0]][index[1]])
            left, right = self.neighbours(ego)
            r[_R["e_l"]], r[_R["e_r"]] = left is not None, right is not None
            # highway-env numbers lanes from the left: negate to route_lane_features' +left
            a_l, a_c, a_r, offset = route_lane_features(-here, frozenset(-g for g in good), 0 <= here - 1,
                                                        here + 1 < n)
            r[_R["a_l"]], r[_R["a_c"]], r[_R["a_r"]], scene["route_lane_offset"] = a_l, a_c, a_r, offset
            s_front = lane.local_coordinates(ego.position)[0] + ego.LENGTH / 2
            remaining = max(float(lane.length) - s_front, 0.0)
            r[_R["d_s"]] = np.clip(remaining / max(float(lane.length), 1e-6), 0.0, 1.0)
            scene["stop_distance_m"] = remaining
        r[_R["dv"]] = np.clip(speed / limit, 0.0, 2.0)
        ego_xy = mirror(ego.position)
        scene["goal_distance_m"] = float("inf") if self.goal_xy is None else float(np.hypot(*(ego_xy - self.goal_xy)))
        return r, scene

    def others(self, ego) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Footprints of every other solid vehicle and obstacle: mirrored centres (K, 2) [m],
        headings (K,) [rad], lengths and widths (K,) [m]."""
        objs = [o for o in (*self.road.vehicles, *self.road.objects) if o is not ego and getattr(o, "solid", True)]
        if not objs:
            empty = np.zeros(0)
            return np.zeros((0, 2)), empty, empty, empty
        xy = mirror(np.array([o.position for o in objs], dtype=float))
        yaw = -np.array([o.heading for o in objs], dtype=float)
        length = np.array([o.LENGTH for o in objs], dtype=float)
        width = np.array([o.WIDTH for o in objs], dtype=float)
        return xy, yaw, length, width

    def occupancy(self, ego) -> np.ndarray:
        """M_t (1, rows, cols) float32 around the ego."""
        xy, yaw, length, width = self.others(ego)
        ego_xy = mirror(ego.position)
        path = None
        if self.config.kind == "deformed" and len(xy):
            s_ego = self.network.get_lane(ego.lane_index).local_coordinates(ego.position)[0]
            path = self.followed_path(ego.lane_index, float(s_ego), getattr(ego, "route", None))
        return occupancy_grid(self.config, ego_xy, -float(ego.heading), path, xy, yaw, length, width)

    def observe(self, ego) -> tuple[dict, dict, np.ndarray]:
        """(observation {"occupancy", "road"}, scene dict, action mask) for the ego now."""
        road, scene = self.road_profile(ego)
        road = road_vector(self.config, road, scene["stop_distance_m"], scene["speed_mps"])
        return {"occupancy": self.occupancy(ego), "road": road}, scene, self.action_mask(ego)
