"""The rule-based expert: the demonstrator for imitation learning and a reference entry.

A lawful, route-aware driver. It reads R_t, M_t and the privileged ``info["scene"]``: speeds
[m/s], distances [m], the lights ahead with their schedules, the leader, the vehicles on links
that conflict with its own through the next junction, the pedestrians near its path and at the
crossings it passes over, how settled the motion planner is on its lane (see
:func:`hbmp_bench.envs.observation.road_profile` and :mod:`hbmp_bench.envs.privileged`). Without
the privileged fields (an env made without ``privileged=True``, or another environment) it falls back to the light ending its lane and the
gap in M_t.

Every speed rule returns :class:`Target` s, "be no faster than ``speed_mps`` once ``at_m`` ahead"
(a stop point has speed 0, a speed cap ``at_m`` 0), optionally only while a zone beyond ``at_m``
is taken (a time window):

``_rule_speed_limit``    cruise at ``cruise_fraction`` of the limit; reach a turn at ``turn_speed_mps``.
``_rule_red_light``      for every light ahead: do not reach its stop line from the end of its green
                         until it is green again (its schedule), and go through a yellow (or a green
                         about to turn) it can no longer stop for.
``_rule_leader_gap``     keep a time gap to the actor ahead in its corridor (vehicle or pedestrian)
                         and room to stop behind it should it brake.
``_rule_junction_clear`` do not enter a junction while the leader stands in it or so close behind it
                         that the ego would stop inside (no blocking the box behind a queue).
``_rule_yield``          stop before the junction (or, inside it, before the conflict area) for a
                         vehicle on a conflicting link that would be in the conflict area while the
                         ego is; a standing foe is passed unless it has the right of way and the ego
                         has not entered the junction yet; a foe held by a red light is passed, unless
                         it comes at it well over its speed limit (it will run the red).
``_rule_pedestrians``    stop before a pedestrian who is in the ego's path or walks into it while the
                         ego would pass, unless a red signal holds them at the kerb of a crossing
                         (before the crossing, where that is on a crossing of its path: a car
                         standing on a crossing is in the way of everyone on it), and for those
                         waiting at a crossing of its path whose signal lets them go.
``_rule_route_lane``     (a lane change, not a speed) move towards the lane that continues the route as
                         soon as the target lane is free and the change fits before the next stop;
                         wait before the lane's end for a gap.

Combination: the route's lane change when it is free and safe; otherwise ``speed_up`` when the
faster speed meets every target for the whole behavior, else ``keep`` when the current speed does
(never at a crawl), else ``speed_down``. A behavior runs 0.1 s in event fidelity, and with the
motion planner until it has converged, 1 to 8 s: each speed is checked over the longest a behavior
plausibly runs (:class:`Timing`), then a stop by a chain of ``speed_down``. With the default
behavior steps (35 % / 3.5 m/s) that chain brakes at about 3.4 m/s² with the planner and at the ego
type's 4.5 m/s² in SUMO (measured from the limit: 27.7 m from 13.8 m/s, 19.1 m from 13.3 m/s); the
expert plans with 3.0 and 3.5 m/s².
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from hbmp_bench.agents.base import PRIVILEGED_OPTION, register_agent
from hbmp_bench.envs.observation import LANE_WIDTH_M, ObservationConfig
from hbmp_bench.planning.behaviors import Behavior, BehaviorConfig, reference_speed
from hbmp_bench.planning.executor import ExecutorConfig
from hbmp_bench.planning.planner import PlannerConfig

SPEED_UP, SPEED_DOWN, CHANGE_LEFT, CHANGE_RIGHT, KEEP = (int(b) for b in Behavior)
EGO_LENGTH_M = 4.5
"""The ego's footprint length [m] (the ``hbmp_ego`` type)."""
RED, YELLOW, GREEN = "rRu", "yY", "gGoOs"
INF = math.inf


@dataclass(frozen=True)
class Target:
    """Be no faster than ``speed_mps`` [m/s] once the front bumper is ``at_m`` [m] ahead of where it is.

    ``hard``: a line the motion planner does not see (a stop line, a conflict area): checked
    against the longest a behavior can run; the others (a leader, a pedestrian, a speed cap)
    against a typical behavior, since the planner itself brakes for actors in its lane.
    ``from_s`` / ``until_s``: the target holds only while a zone beyond ``at_m`` is taken (a red
    phase, a foe or a pedestrian crossing) [s from now]; a car that, at the speed it drives, has
    left the zone (``zone_m`` [m] beyond ``at_m``, its own length included) before ``from_s`` or
    gets to ``at_m`` after ``until_s`` need not stop. Always taken if (0, inf).
    """

    at_m: float
    speed_mps: float
    rule: str = ""
    hard: bool = False
    from_s: float = 0.0
    until_s: float = INF
    zone_m: float = 0.0

    def passes_outside(self, v: float, v_to: float, v_then: float = 0.0) -> bool:
        """Whether a car at ``v`` [m/s] that goes to ``v_to`` and holds it misses the window: it
        leaves the zone before it (accelerating gently, at 1.5 m/s², to ``v_to`` or to ``v_then``,
        the speed the next decisions' speed_up reach: :attr:`Timing.chain_mps`) or gets there after
        it (at ``v_to`` at once)."""
        if self.from_s <= 0.0 and self.until_s == INF:
            return False
        leave_s = ExpertAgent._time_to(self.at_m + self.zone_m, v, accel=1.5, v_max=max(v_to, v_then))
        enter_s = max(self.at_m, 0.0) / max(v, v_to, 0.1)
        return leave_s < self.from_s or enter_s > self.until_s


@dataclass(frozen=True)
class Timing:
    """How long the expert assumes a behavior may run before it decides again [s], and how a chain
    of ``speed_down`` stops.

    Continuous fidelity: a behavior ends once the planner has converged (a lane change to its
    lane, speed_up / speed_down to their speed, keep at once), after at least
    ``ExecutorConfig.min_duration`` (1 s); speed_up and speed_down after at most
    ``lane_keeping_max_duration`` (2 s), a lane change after at most ``max_duration`` (8 s).
    ``hard_s`` / ``keep_hard_s`` / ``lane_change_hard_s`` are those longest runs (keep: exactly
    1 s), checked against the lines the planner does not see (stop lines, conflict areas); the
    typical runs (``keep_s``, ``speed_up_s``, ``lane_change_s``) against the actors the planner
    itself brakes for (``keep_s`` longer than keep runs: room for a leader that brakes). Event
    fidelity: every behavior lasts one decision period.
    """

    keep_s: float
    speed_up_s: float
    lane_change_s: float
    hard_s: float
    lane_change_hard_s: float
    stop_decel: float
    accel: float
    keep_hard_s: float
    chain_mps: float = 0.0
    """The speed a chain of speed_up decisions reaches while the ego leaves a zone ahead [m/s]
    (:meth:`Target.passes_outside`; 0: no further speed_up is counted on)."""
    crawl_s: float = 0.1
    """How long a lane change begun below 2 m/s may run (slow to converge sideways) [s]."""

    @staticmethod
    def for_period(period_s: float, continuous: bool, executor: ExecutorConfig = ExecutorConfig()) -> "Timing":
        """Timing of a behavior in event fidelity (``period_s``) or with the motion planner
        (``executor``: its longest runs)."""
        if continuous:
            return Timing(keep_s=1.5, speed_up_s=executor.lane_keeping_max_duration, lane_change_s=3.0,
                          hard_s=executor.lane_keeping_max_duration, lane_change_hard_s=executor.max_duration,
                          stop_decel=3.0, accel=INF, keep_hard_s=executor.min_duration, crawl_s=executor.max_duration)
        p = max(period_s, 0.1)
        return Timing(keep_s=p, speed_up_s=p, lane_change_s=p, hard_s=p, lane_change_hard_s=p, stop_decel=3.5,
                      accel=2.6, keep_hard_s=p, crawl_s=p)


@register_agent("expert")
class ExpertAgent:
    """Lawful, route-aware rule-based driver (see the module docstring for its rules).

    Args:
        cruise_fraction: cruise speed as a fraction of the speed limit.
        turn_speed_mps: speed it reaches a turning junction with (``scene["turn_ahead"]``) [m/s].
        stop_margin_m: distance it stops before a stop line, a conflict area or a pedestrian [m].
        standstill_gap_m: gap it keeps to a standing leader [m].
        time_gap_s: time gap it keeps to a leader [s].
        leader_decel: deceleration it allows a leader to brake with [m/s²].
        foe_margin_s: time kept between the ego and a junction foe in a conflict area [s].
        grid: the M_t grid it reads (must match the environment's).
        behavior: the v_ref rule of speed_up / speed_down (must match the environment's).
        executor: the motion planner's behavior timing (must match the environment's).
        planner: the motion planner's curve speed limits (must match the environment's).

    Attributes:
        env_kwargs: the env options it asks for: ``privileged=True`` (the privileged scene fields;
            an evaluation marks its results privileged).
    """

    name = "expert"

    def __init__(self, cruise_fraction: float = 0.9, turn_speed_mps: float = 6.0, stop_margin_m: float = 2.0,
                 standstill_gap_m: float = 3.0, time_gap_s: float = 1.2, leader_decel: float = 4.5,
                 foe_margin_s: float = 1.5, grid: ObservationConfig | None = None,
                 behavior: BehaviorConfig | None = None, executor: ExecutorConfig | None = None,
                 planner: PlannerConfig | None = None):
        self.cruise_fraction = cruise_fraction
        self.turn_speed_mps = turn_speed_mps
        self.stop_margin_m = stop_margin_m
        self.standstill_gap_m = standstill_gap_m
        self.time_gap_s = time_gap_s
        self.leader_decel = leader_decel
        self.foe_margin_s = foe_margin_s
        self.grid = grid or ObservationConfig()
        self.behavior = behavior or BehaviorConfig()
        self.executor = executor or ExecutorConfig()
        self.planner = planner or PlannerConfig()
        self.env_kwargs = {PRIVILEGED_OPTION: True}
        self._stuck_s = 0.0

    def reset(self, info):
        self._stuck_s = 0.0

    # ------------------------------------------------------------- kinematics
    def _timing(self, scene: dict, info: dict) -> Timing:
        period = float(info.get("duration_s", 0.1))
        fidelity = scene.get("fidelity")
        continuous = fidelity == "continuous" if fidelity else period > 0.2
        t = Timing.for_period(period, continuous, self.executor)
        return dataclasses.replace(t, chain_mps=self._chain_speed(scene, continuous))

    def _chain_speed(self, scene: dict, continuous: bool) -> float:
        """The speed [m/s] a chain of speed_up decisions reaches while the ego leaves a zone ahead
        (a crossing, a conflict area), at most 8 m/s: with SUMO's 0.1 s decisions 8; with the motion
        planner (a decision about every second) also at most the cruise speed and the planner's
        curve speed cap on the sharpest curvature of the path ahead (``curvature_ahead``), 0 where
        that is unknown."""
        if not continuous:
            return 8.0
        kappa = scene.get("curvature_ahead")
        if kappa is None:
            return 0.0
        cap = min(8.0, self.cruise_fraction * scene["speed_limit_mps"])
        if kappa > 1e-6:
            cap = min(cap, math.sqrt(self.planner.curve_lat_accel / kappa), self.planner.yaw_rate_max / kappa)
        return cap

    @staticmethod
    def _time_to(distance_m: float, v: float, accel: float = 2.0, v_max: float = INF) -> float:
        """Time [s] to drive ``distance_m`` from speed ``v`` accelerating at ``accel`` up to ``v_max``."""
        if distance_m <= 0.0:
            return 0.0
        if accel <= 0.0 or v_max <= v:
            return distance_m / v if v > 0.0 else INF
        v_max = max(v_max, 0.1)
        t_acc = (v_max - v) / accel
        d_acc = v * t_acc + 0.5 * accel * t_acc * t_acc
        if distance_m <= d_acc:
            return (-v + math.sqrt(v * v + 2.0 * accel * distance_m)) / accel
        return t_acc + (distance_m - d_acc) / v_max

    @staticmethod
    def _meets(targets: list[Target], v: float, v_to: float, hold_s: float, t: Timing, tolerance: float,
               hard_s: float | None = None) -> bool:
        """Whether a behavior that takes the speed from ``v`` to ``v_to`` and holds it for
        ``hold_s`` [s] (its longest run ``hard_s``, default ``t.hard_s``, for hard targets) still
        lets a chain of speed_down meet every target; a speed cap may be exceeded by ``tolerance``
        [m/s], a stop never."""
        hard_s = t.hard_s if hard_s is None else hard_s
        for g in targets:
            if v_to <= g.speed_mps + (tolerance if g.speed_mps > 0.0 else 0.0) or g.passes_outside(v, v_to, t.chain_mps):
                continue
            travel = max(v, v_to) * (hard_s if g.hard else hold_s)
            if g.at_m <= 0.0 or travel + (v_to ** 2 - g.speed_mps ** 2) / (2.0 * t.stop_decel) > g.at_m:
                return False
        return True

    def _stop_possible(self, v: float, distance_m: float, t: Timing) -> bool:
        """Whether the ego stands, or a chain of speed_down starting now stops it before
        ``distance_m`` [m] (less the margin)."""
        return v < 0.5 or v * v / (2.0 * t.stop_decel) <= distance_m - self.stop_margin_m

    # ------------------------------------------------------------------ M_t
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

    def _gap_ahead(self, occupancy: np.ndarray) -> float:
        """Distance [m] from the ego's front to the first occupied row ahead in its lane (inf if none)."""
        g = self.grid
        offsets = np.arange(g.rows) * g.cell_long_m - g.back_m
        ahead = self._corridor(occupancy, 0) & (offsets >= 0.0)
        return float(offsets[ahead][0] - EGO_LENGTH_M / 2) if ahead.any() else INF

    def _lane_free(self, occupancy: np.ndarray, side: int, v: float) -> bool:
        """Whether the lane ``side`` (+1 left, -1 right) is free from 10 m behind (more at speed) to
        15 m ahead of the ego."""
        g = self.grid
        offsets = np.arange(g.rows) * g.cell_long_m - g.back_m
        window = (offsets >= -min(10.0 + v, g.back_m)) & (offsets <= 15.0)
        return not self._corridor(occupancy, side)[window].any()

    # ---------------------------------------------------------------- rules
    def _rule_speed_limit(self, scene: dict, t: Timing) -> list[Target]:
        out = [Target(0.0, self.cruise_fraction * scene["speed_limit_mps"], "speed_limit")]
        if scene.get("turn_ahead", "") in ("l", "L", "r", "R") and not scene["in_junction"]:
            out.append(Target(scene["stop_distance_m"], self.turn_speed_mps, "turn"))
        return out

    def _rule_red_light(self, scene: dict, t: Timing) -> list[Target]:
        lights = scene.get("lights_ahead")
        if lights is None:  # no privileged lights: the one ending the lane (R_t's)
            lights = ((scene["stop_distance_m"], scene["light"], ((0.0, scene["light"]),)),) if scene["light"] else ()
        return [g for light in lights for g in self._light_target(light, scene["speed_mps"], t)]

    def _light_target(self, light: tuple, v: float, t: Timing) -> list[Target]:
        """The target of one light (distance to its stop line [m], signal, schedule): do not reach
        the line from the end of its green until it is green again; nothing for a yellow (or a
        green about to turn) the ego can no longer stop for."""
        d, signal, schedule = light
        if signal not in RED + YELLOW + GREEN or not math.isfinite(d):
            return []
        if signal not in RED and not self._stop_possible(v, d, t):
            return []  # go through
        schedule = schedule or ((0.0, signal),)
        stop_from = next((at for at, c in schedule if c not in GREEN), INF)
        if stop_from == INF:
            return []
        green_again = next((at for at, c in schedule if at > stop_from and c in GREEN), INF)
        return [Target(d - self.stop_margin_m, 0.0, "red_light", hard=True, from_s=max(stop_from - 0.5, 0.0),
                       until_s=green_again + 0.5, zone_m=self.stop_margin_m)]

    def _rule_leader_gap(self, scene: dict, occupancy: np.ndarray, t: Timing) -> list[Target]:
        gap = scene.get("leader_gap_m")
        v_lead = max(float(scene.get("leader_speed_mps", 0.0)), 0.0)
        if gap is None:
            gap, v_lead = self._gap_ahead(occupancy), 0.0
        if not math.isfinite(gap):
            return []
        room = gap - self.standstill_gap_m
        stop_at = room + v_lead * v_lead / (2.0 * self.leader_decel)
        return [Target(stop_at, 0.0, "leader"), Target(0.0, max(room, 0.0) / self.time_gap_s, "time_gap")]

    def _rule_junction_clear(self, scene: dict, t: Timing) -> list[Target]:
        if scene["in_junction"]:
            return []
        d, exit_m = scene["stop_distance_m"], scene.get("junction_exit_m", INF)
        gap, v_lead = scene.get("leader_gap_m", INF), scene.get("leader_speed_mps", 0.0)
        if not (math.isfinite(exit_m) and math.isfinite(gap)) or d < 0.5:
            return []
        # the leader stands in the junction, or so close behind it that the ego would stop inside
        blocked = d - 1.0 < gap < exit_m + EGO_LENGTH_M + self.standstill_gap_m and v_lead < 1.0
        return [Target(d - 1.0, 0.0, "junction_clear", hard=True)] if blocked else []

    def _rule_yield(self, scene: dict, t: Timing) -> list[Target]:
        out = []
        before_line = not scene["in_junction"] and scene["stop_distance_m"] > 0.5
        exit_m = scene.get("junction_exit_m", INF)
        for f in scene.get("junction_foes", ()):
            if f["ego_dist_m"] > exit_m:
                continue  # a conflict at a later junction: judged once the ego has crossed this one
            held = f["foe_signal"] and f["foe_signal"] in RED and not f.get("foe_speeding")
            if held or f["ego_exit_m"] + EGO_LENGTH_M < 0.0 or f["foe_exit_m"] + EGO_LENGTH_M < 0.0:
                continue  # held by its light (unless it speeds at it), or one has passed the conflict area
            if f["ego_dist_m"] <= 0.5:
                continue  # the ego is in the conflict area: clear it
            v_foe = f["foe_speed_mps"]
            if v_foe < 0.5 and not (f["ego_yields"] and before_line):
                continue  # it stands: for the ego (its right of way, or the ego is in the junction already)
            # when the foe is in the conflict area (a standing foe may start at any time)
            foe_in = self._time_to(f["foe_dist_m"], v_foe, accel=2.6 if v_foe < 0.5 else 0.0)
            foe_out = self._time_to(f["foe_exit_m"] + EGO_LENGTH_M, v_foe, accel=2.6 if v_foe < 0.5 else 0.0)
            at = scene["stop_distance_m"] - 1.0 if before_line else f["ego_dist_m"] - self.stop_margin_m
            out.append(Target(at, 0.0, "yield", hard=True, from_s=foe_in - self.foe_margin_s,
                              until_s=foe_out + self.foe_margin_s, zone_m=f["ego_exit_m"] + EGO_LENGTH_M - at))
        return out

    def _rule_pedestrians(self, scene: dict, t: Timing) -> list[Target]:
        out = []
        ahead = [c for c in scene.get("crossings", ()) if c["ego_dist_m"] >= 0.5]
        for s, d, v_s, v_d, held in scene.get("pedestrians", ()):
            if s < 0.5:
                continue  # beside or behind the front bumper: driving on takes the ego away
            # the ego's half width and a margin: wider for a walking pedestrian than for one who
            # stands (e.g. at the kerb, waiting to cross)
            w = 0.9 + (1.0 if math.hypot(v_s, v_d) > 0.2 else 0.5)
            if abs(d) < w:
                p_in, meet = 0.0, s
                p_out = (math.copysign(w, v_d) - d) / v_d if abs(v_d) > 0.2 else INF
            elif d * v_d < 0.0 and abs(v_d) > 0.2 and not (held and abs(d) > w + LANE_WIDTH_M / 2):
                # (one a red signal holds at the kerb is not followed into the path before it is
                # within half a lane of the ego's corridor: a kerb at a corner may lie that close)
                p_in, p_out = (abs(d) - w) / abs(v_d), (abs(d) + w) / abs(v_d)
                meet = s - v_s * d / v_d  # where its walk meets the path
            else:
                continue
            # one who is on, or walks onto, the ego's path over a crossing walks the crossing's
            # length (obliquely to a turning path, and through a car standing on it): stop before
            # the crossing, not on it
            at = min([s] + [c["ego_dist_m"] for c in ahead if c["ego_dist_m"] <= meet <= c["ego_exit_m"]]) \
                - self.stop_margin_m
            at = self._off_crossings(at, ahead)
            out.append(Target(at, 0.0, "pedestrian", hard=True, from_s=p_in - 1.0, until_s=p_out + 1.0,
                              zone_m=s - at + EGO_LENGTH_M + 1.0))
        # a pedestrian waiting at a crossing of the ego's path steps onto it when the signal lets
        # them (walking at 1 to 1.5 m/s)
        for c in scene.get("crossings", ()):
            if (c["signal"] and c["signal"] in RED + YELLOW) or c["ego_dist_m"] < 0.5:
                continue  # held by their signal, or the ego is on the crossing already: clear it
            at = self._off_crossings(c["ego_dist_m"] - self.stop_margin_m, ahead)
            for gap in c["waiting_m"]:
                out.append(Target(at, 0.0, "pedestrian", hard=True, from_s=max(gap - 2.5, 0.0) / 1.5 - 1.0,
                                  until_s=(gap + 2.5) / 1.0 + 1.0,
                                  zone_m=c["ego_exit_m"] - at + EGO_LENGTH_M))
        return out

    def _off_crossings(self, at_m: float, crossings) -> float:
        """Where to stop for a stop point ``at_m`` ahead [m] so that the car stands on none of the
        ``crossings`` ahead (pedestrians walk through a car on their crossing): at ``at_m``, or
        before the nearest crossing whose stretch its body would still cover there (two crossings
        of a turn at a junction corner may lie less than a car length apart)."""
        for c in sorted(crossings, key=lambda c: -c["ego_dist_m"]):  # farthest first: a chain
            if c["ego_dist_m"] < at_m < c["ego_exit_m"] + EGO_LENGTH_M:
                at_m = c["ego_dist_m"] - self.stop_margin_m
        return at_m

    def _rule_route_lane(self, scene: dict, occupancy: np.ndarray, mask: np.ndarray, t: Timing,
                         road: np.ndarray, targets: list[Target]) -> tuple[int | None, list[Target]]:
        """(a lane change toward the route's lanes, or None; where to wait for a gap)."""
        if scene["in_junction"]:
            return None, []
        v, offset, d = scene["speed_mps"], scene["route_lane_offset"], scene["stop_distance_m"]
        if offset == 0:
            return self._pass_standing_obstacle(scene, occupancy, mask, t, road, targets), []
        action = CHANGE_LEFT if offset > 0 else CHANGE_RIGHT
        if mask[action] and self._lane_free(occupancy, 1 if offset > 0 else -1, v) and self._lane_change_safe(scene, targets, t):
            return action, []
        if not mask[action] or road[3] > 0.5:
            return None, []
        # wait for a gap where lane changes are still open (room for one at the lane-change speed);
        # past that point drive on: the route is re-planned from where the lane leads. On the goal's
        # edge the lane leads on past the goal: the change must be done before the goal point
        room = 16.0 if t.keep_s > 0.2 else 12.0
        d = min(d, scene.get("goal_distance_m", INF) - EGO_LENGTH_M / 2)
        return None, ([Target(d - room, 0.0, "route_lane", hard=True)] if d - room > 0.0 else [])

    def _pass_standing_obstacle(self, scene: dict, occupancy: np.ndarray, mask: np.ndarray, t: Timing,
                                road: np.ndarray, targets: list[Target]) -> int | None:
        """On the route's lane, standing behind a standing obstacle away from junctions for over 5 s: a lane
        change past it onto a lane that also continues the route, where one is free and safe (None: wait)."""
        v, d = scene["speed_mps"], scene["stop_distance_m"]
        gap = scene.get("leader_gap_m", INF)
        standing = v < 0.5 and gap < 15.0 and scene.get("leader_speed_mps", 0.0) < 0.5 and d > 40.0
        self._stuck_s = self._stuck_s + t.keep_s if standing else 0.0
        if self._stuck_s > 5.0:
            for side, action, alpha in ((1, CHANGE_LEFT, road[2]), (-1, CHANGE_RIGHT, road[4])):
                if mask[action] and alpha > 0.5 and self._lane_free(occupancy, side, v) and \
                        self._lane_change_safe(scene, targets, t):
                    self._stuck_s = 0.0
                    return action
        return None

    def _lane_change_safe(self, scene: dict, targets: list[Target], t: Timing) -> bool:
        """Whether a lane change (at least ``min_lane_change_speed``, held for a whole behavior)
        meets every target. The next stop line is judged with the signal of the lane it changes to
        (``route_lane_light``); without it, as red."""
        v = scene["speed_mps"]
        v_lc = max(v, self.behavior.min_lane_change_speed)
        lights = scene.get("lights_ahead") or (((scene["stop_distance_m"], scene["light"], ()),) if scene["light"] else ())
        lines = [g for g in targets if g.rule != "red_light" or not lights or g.at_m > lights[0][0]]
        if scene.get("route_lane_light"):  # the signal of the lane it changes to
            lines += self._light_target(scene["route_lane_light"], v, t)
        elif lights:  # unknown: counts as red
            lines.append(Target(lights[0][0] - self.stop_margin_m, 0.0, "red_light", hard=True))
        hold = t.lane_change_s if v >= 2.0 else max(t.lane_change_s, t.crawl_s)
        return self._meets(lines, v, v_lc, hold, t, tolerance=1.0, hard_s=t.lane_change_hard_s)

    # ---------------------------------------------------------------- act
    def targets(self, observation: dict, info: dict) -> list[Target]:
        """Every speed target of the rules now (for inspection and tests)."""
        scene, occ = info["scene"], observation["occupancy"]
        t = self._timing(scene, info)
        return [*self._rule_speed_limit(scene, t), *self._rule_red_light(scene, t),
                *self._rule_leader_gap(scene, occ, t), *self._rule_junction_clear(scene, t),
                *self._rule_yield(scene, t), *self._rule_pedestrians(scene, t)]

    def act(self, observation, info):
        scene, mask, road = info["scene"], info["action_mask"], observation["road"]
        occ = observation["occupancy"]
        t = self._timing(scene, info)
        v, limit = scene["speed_mps"], scene["speed_limit_mps"]
        targets = self.targets(observation, info)
        change, waits = self._rule_route_lane(scene, occ, mask, t, road, targets)
        if change is not None:
            return change
        targets += waits

        v_up = min(reference_speed(SPEED_UP, v, limit, self.behavior), v + t.accel * t.speed_up_s)
        if v_up > v + 0.05 and self._meets(targets, v, v_up, t.speed_up_s, t, tolerance=1.0):
            return SPEED_UP
        creeping = 0.05 < v < 1.0 and t.crawl_s > 1.0  # the planner converges slowly at a crawl: stop instead
        if not creeping and self._meets(targets, v, v, t.keep_s, t, tolerance=0.3, hard_s=t.keep_hard_s):
            return KEEP
        return SPEED_DOWN
