"""The rule-based expert: the demonstrator for imitation learning and a reference entry.

It reads M_t for obstacles and the privileged ``info["scene"]`` (speed [m/s], speed limit,
distance to the stop line [m], light state, signed lane offset to a lane that continues the
route) that the environment computes from the road map.

Rules, in order: stop for a red (or a yellow it can still stop for) before the stop line; keep a
braking distance to the nearest obstacle in its lane corridor; move toward the lane that
continues the route before each junction when the target lane is free; overtake a standing
obstacle when a neighbouring lane that also continues the route is free; otherwise cruise near
the speed limit.
"""

from __future__ import annotations

import numpy as np

from hbmp_bench.agents.base import register_agent
from hbmp_bench.envs.observation import ObservationConfig

SPEED_UP, SPEED_DOWN, CHANGE_LEFT, CHANGE_RIGHT, KEEP = range(5)
LANE_WIDTH_M = 3.5


@register_agent("expert")
class ExpertAgent:
    """Route-aware rule-based driver.

    Args:
        cruise_fraction: cruise speed as a fraction of the speed limit.
        comfort_decel: deceleration it plans stops with when it decides every 0.1 s [m/s²].
        behavior_decel: deceleration it plans stops with when behaviors last ~1 s (motion
            planner): what a chain of speed_down behaviors achieves (v_ref steps of
            max(20 %, 2 m/s) per ~1 s behavior) [m/s²].
        stop_margin_m: distance kept to a stop line or an obstacle [m].
        turn_speed_mps: speed it reaches a turning junction with (``scene["turn_ahead"]``) [m/s].
        grid: the M_t grid it reads (must match the environment's).
    """

    name = "expert"

    def __init__(self, cruise_fraction: float = 0.9, comfort_decel: float = 3.0, behavior_decel: float = 1.8,
                 stop_margin_m: float = 5.0, turn_speed_mps: float = 6.0, grid: ObservationConfig | None = None):
        self.turn_speed_mps = turn_speed_mps
        self.cruise_fraction = cruise_fraction
        self.comfort_decel = comfort_decel
        self.behavior_decel = behavior_decel
        self._decel = comfort_decel
        self.stop_margin_m = stop_margin_m
        self.grid = grid or ObservationConfig()
        self._stuck_s = 0.0

    def reset(self, info):
        self._stuck_s = 0.0

    # ------------------------------------------------------------- helpers
    def _corridor(self, occupancy: np.ndarray, lane_offset: int, half_width_m: float = 1.6) -> np.ndarray:
        """Occupied flags per row (rows,) in the corridor of the lane ``lane_offset`` lanes to the left."""
        g = self.grid
        centre = g.cols / 2 + lane_offset * LANE_WIDTH_M / g.cell_lat_m
        half = half_width_m / g.cell_lat_m
        lo, hi = int(np.floor(centre - half)), int(np.ceil(centre + half))
        lo, hi = max(lo, 0), min(hi, g.cols)
        if lo >= hi:
            return np.zeros(g.rows, dtype=bool)
        return occupancy[0, :, lo:hi].any(axis=1)

    def _gap_ahead(self, rows: np.ndarray) -> float:
        """Distance [m] from the ego's front to the first occupied row ahead (inf if none)."""
        g = self.grid
        offsets = np.arange(g.rows) * g.cell_long_m - g.back_m
        ahead = rows & (offsets >= 0.0)
        return float(offsets[ahead][0] - 2.25) if ahead.any() else float("inf")

    def _lane_free(self, occupancy: np.ndarray, side: int) -> bool:
        g = self.grid
        offsets = np.arange(g.rows) * g.cell_long_m - g.back_m
        window = (offsets >= -10.0) & (offsets <= 15.0)
        return not self._corridor(occupancy, side)[window].any()

    def _stop_speed(self, distance_m: float) -> float:
        return float(np.sqrt(2.0 * self._decel * max(distance_m - self.stop_margin_m, 0.0)))

    # ---------------------------------------------------------------- act
    def act(self, observation, info):
        occ, scene, mask = observation["occupancy"], info["scene"], info["action_mask"]
        road = observation["road"]
        v, limit = scene["speed_mps"], scene["speed_limit_mps"]
        target = self.cruise_fraction * limit
        # a behavior runs ~ as long as the last one did (0.1 s in event fidelity, ~1 s with the
        # motion planner): judge distances from where the ego will be when it can act again
        period = float(np.clip(info.get("duration_s", 0.1), 0.1, 1.5))
        travel = v * period
        self._decel = self.comfort_decel if period <= 0.2 else min(self.comfort_decel, self.behavior_decel)

        gap = self._gap_ahead(self._corridor(occ, 0))
        light, d_stop = scene["light"], scene["stop_distance_m"]
        can_stop = v * v / (2 * self._decel) < d_stop - 1.0  # braking could start now
        must_stop = light in ("r", "R", "u") or (light in ("y", "Y") and can_stop)
        # where the ego must be standing by: behind the car ahead, before a red stop line, and,
        # in a lane that does not continue the route, early enough to change lanes from there
        stop_at = gap
        if must_stop:
            stop_at = min(stop_at, d_stop + self.stop_margin_m - 1.0)
        offset = scene["route_lane_offset"]
        change = CHANGE_LEFT if offset > 0 else CHANGE_RIGHT
        if not scene["in_junction"] and road[3] < 0.5 and d_stop < 30.0 and (offset == 0 or mask[change]):
            # wait for a gap to the route's lane, early enough to change lanes from there; once
            # lane changes are closed (last metres of the lane) drive on: the route is re-planned
            room_to_change = 16.0 if period > 0.2 else 12.0  # > the lane-change cutoff (10 m)
            stop_at = min(stop_at, d_stop + self.stop_margin_m - 1.0 - room_to_change)
        target = min(target, self._stop_speed(stop_at - travel))
        if scene.get("turn_ahead", "") in ("l", "L", "r", "R"):
            # reach a turn at turn speed, so it is not taken braking in the junction (or on red)
            room = max(d_stop - travel - 5.0, 0.0)
            target = min(target, float(np.sqrt(self.turn_speed_mps ** 2 + 2 * self._decel * room)))

        self._stuck_s = self._stuck_s + period if (v < 0.5 and gap < 15.0 and not must_stop) else 0.0
        if not scene["in_junction"]:
            if offset != 0:
                side = 1 if offset > 0 else -1
                action = CHANGE_LEFT if side > 0 else CHANGE_RIGHT
                if mask[action] and self._lane_free(occ, side):
                    return action
            elif self._stuck_s > 3.0:
                for side, action, alpha in ((1, CHANGE_LEFT, road[2]), (-1, CHANGE_RIGHT, road[4])):
                    if mask[action] and alpha > 0.5 and self._lane_free(occ, side):
                        self._stuck_s = 0.0
                        return action

        if v > target + 0.3 or (target < 0.5 and v > 0.0):
            return SPEED_DOWN
        # speed_up sets v_ref = v + max(20 %, 2 m/s) and holds it for a whole behavior: only
        # when that speed is still safe (decisions every 0.1 s can take smaller steps)
        if v < target - 1.0:
            if period <= 0.2:
                return SPEED_UP
            v_new = v + max(0.2 * v, 2.0)
            after = stop_at - 0.5 * (v + v_new) * period  # where the next decision happens
            if v_new <= target + 0.5 and v_new <= self._stop_speed(after):
                return SPEED_UP
        return KEEP
