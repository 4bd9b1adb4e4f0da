"""Privileged quantities of ``info["scene"]``: what the rule-based expert reads besides M_t and R_t.

A learned agent sees only M_t and R_t; the expert (:mod:`hbmp_bench.agents.expert`), a
demonstrator, may read the simulator's state. :class:`PrivilegedScene` adds these fields to the
scene of :func:`hbmp_bench.envs.observation.road_profile`: those of :func:`path_actors` (geometry
of the actors near the path), and


  lights_ahead     the traffic lights on the route within ``LIGHTS_RANGE_M``, nearest first (also
                   beyond junctions without lights, unlike R_t's l_g/l_y/l_r and ``light``): one
                   (distance from the front bumper to the stop line [m], signal char, schedule) per
                   light, the schedule ((0, char now), (seconds until the next change, char), ...)
                   of its link for the next minute
  route_lane_light the light of the link onto the route's next edge from the lane that continues the
                   route, where the ego is in another lane: (distance [m], signal char, schedule)
                   as in ``lights_ahead``, () otherwise (a lane change may lead to another signal)
  junction_exit_m  distance from the front bumper to the end of the junction the route crosses
                   next (or is crossing) [m]; inf after the last junction
  junction_foes    the vehicles on or before (up to ``FOE_RANGE_M``) the links that conflict with
                   the ego's link through the junction ahead (or the one it is in), see
                   :func:`junction_foes`
  crossings        the pedestrian crossings the ego's link through the junction ahead (or the one
                   it is in) passes over: one dict per crossing with ``ego_dist_m`` / ``ego_exit_m``
                   (ego front to the start / end of the stretch of its path over the crossing [m]),
                   ``signal`` (the pedestrians' signal char, "" without a light) and ``waiting_m``
                   (distance [m] from each pedestrian waiting to step onto it to that stretch); a
                   pedestrian waiting at one whose signal is red or yellow is held there (SUMO's
                   pedestrians step onto a crossing on green only): its ``pedestrians`` entry says so
  fidelity         the world's fidelity (``event`` or ``continuous``)
  lane_error_m, heading_error_rad, curvature_ahead
                   continuous fidelity only: the ego's lateral offset [m] and heading error [rad]
                   from the centreline the motion planner tracks, and that centreline's sharpest
                   curvature [1/m] over the next 3 s (a lane change begun with small errors on a
                   straight stretch ends after about its minimum duration, otherwise it may run to
                   the planner's maximum, 8 s; keep ends after its minimum duration, speed_up and
                   speed_down once at their speed, after at most 2 s, see
                   :mod:`hbmp_bench.planning.executor`)
"""

from __future__ import annotations

import functools
import math

import numpy as np

from hbmp_bench.envs.observation import RED, YELLOW, followed_path
from hbmp_bench.maps.roadnet import Connection, RoadNetwork, point_along, project_on_polyline
from hbmp_bench.metrics.geometry import stop_line_of
from hbmp_bench.planning.frame import Path
from hbmp_bench.sim.sumo import Actors, LightAhead, SumoSim, VehicleState, VehicleType

LEADER_RANGE_M = 100.0
"""Farthest leader reported, from the ego's front bumper [m]."""
PEDESTRIAN_RANGE_M = 50.0
"""Pedestrians up to this far ahead of the front bumper along the path are reported [m] ..."""
PEDESTRIAN_LATERAL_M = 10.0
"""... when within this lateral distance of the path [m]."""
CORRIDOR_MARGIN_M = 0.3
"""An actor is in the ego's corridor when its footprint comes within the ego's half width plus
this margin of the path [m]."""
LIGHTS_RANGE_M = 150.0
"""Traffic lights up to this far ahead are reported [m]."""
FOE_RANGE_M = 80.0
"""Vehicles up to this far before a conflicting link are reported [m]."""


def path_actors(path: Path, ego_xy: np.ndarray, ego_length: float, ego_width: float, xy: np.ndarray,
                yaw: np.ndarray, speed: np.ndarray, length: np.ndarray, width: np.ndarray,
                is_pedestrian: np.ndarray, held: np.ndarray | None = None) -> dict:
    """The actors near the followed lane's centreline ``path``, measured along it.

    Args:
        path: the centreline the ego follows (its lane, through the junctions of its route).
        ego_xy: (2,) ego footprint centre [m]; ego_length / ego_width: its footprint [m].
        xy, yaw, speed, length, width, is_pedestrian: (K,) the other actors (centres [m],
            headings [rad], speeds [m/s], footprints [m]).
        held: (K,) bool, the pedestrians a red signal holds at the kerb of a crossing (default none).

    Returns:
        ``leader_gap_m``: free distance from the ego's front bumper to the nearest actor ahead
        whose footprint lies in the ego's corridor (vehicle or pedestrian), inf if none within
        ``LEADER_RANGE_M``; ``leader_speed_mps``: that actor's speed along the path [m/s] (0 if
        none; negative when it comes towards the ego); ``pedestrians``: ((s, d, v_s, v_d, held),
        ...) for every pedestrian ahead within ``PEDESTRIAN_RANGE_M`` and ``PEDESTRIAN_LATERAL_M``:
        its distance along the path from the ego's front bumper [m], signed lateral offset (left
        positive) [m], velocity along / across the path (left positive) [m/s] and ``held``,
        nearest first.
    """
    out = {"leader_gap_m": float("inf"), "leader_speed_mps": 0.0, "pedestrians": ()}
    if len(xy) == 0:
        return out
    s_ego = path.project_pose(ego_xy[0], ego_xy[1], 0.0)[0]  # compiled projections: Path.project's floats
    front = float(s_ego) + ego_length / 2
    near = np.hypot(*(xy - ego_xy).T) < LEADER_RANGE_M + ego_length + 10.0
    if not near.any():
        return out
    idx = np.nonzero(near)[0]
    s, d, theta = path.project_poses(xy[idx], yaw[idx])
    c, sn = np.abs(np.cos(theta)), np.abs(np.sin(theta))
    half_long = length[idx] / 2 * c + width[idx] / 2 * sn
    half_lat = length[idx] / 2 * sn + width[idx] / 2 * c
    gap = s - half_long - front
    v_s, v_d = speed[idx] * np.cos(theta), speed[idx] * np.sin(theta)
    in_corridor = (np.abs(d) - half_lat < ego_width / 2 + CORRIDOR_MARGIN_M) & (s > front) & (gap < LEADER_RANGE_M)
    if in_corridor.any():
        k = int(np.argmin(np.where(in_corridor, gap, np.inf)))
        out["leader_gap_m"] = float(max(gap[k], 0.0))
        out["leader_speed_mps"] = float(v_s[k])
    ped = is_pedestrian[idx] & (s - front > -ego_length) & (s - front < PEDESTRIAN_RANGE_M) & (np.abs(d) < PEDESTRIAN_LATERAL_M)
    order = np.argsort(s[ped])
    held = np.zeros(len(xy), dtype=bool) if held is None else np.asarray(held, dtype=bool)
    out["pedestrians"] = tuple((float(a), float(b), float(e), float(f), bool(h)) for a, b, e, f, h in
                               zip((s[ped] - front)[order], d[ped][order], v_s[ped][order], v_d[ped][order],
                                   held[idx][ped][order]))
    return out


def gives_way(signal: str, state: str, other_signal: str, other_state: str) -> bool:
    """Whether a link must give way to another at the junction: with lights, a permissive green
    (``g``) to a priority green (``G``); without, a minor or stop link (``m``, ``s``) to a major
    one (``M``). Links of equal rank (``=``, all-way stops, two permissive greens) give way to
    neither."""
    if signal and other_signal:
        return signal == "g" and other_signal == "G"
    if not signal and not other_signal:
        return state in "ms" and other_state == "M"
    return False


SPEEDING_FACTOR = 1.2
"""A foe faster than this times its lane's limit is ``foe_speeding``: a driver who will not stop for its
red (SUMO's own keep within a few percent of the limit: ``--default.speeddev 0.05``)."""


def junction_foes(entry_m: float, signal: str, state: str, conflicts, users, foe_signals,
                  foe_limits=None) -> tuple[dict, ...]:
    """The ``junction_foes`` of the scene: one dict per vehicle on a conflicting link.

    Args:
        entry_m: distance from the ego's front bumper to the start of its link [m] (negative inside).
        signal / state: the ego link's signal char ("" without a light) and static state.
        conflicts: the :class:`hbmp_bench.maps.roadnet.LinkConflict` s of the ego's link.
        users: per conflict, the vehicles on or before the foe link: (id, distance from the
            front bumper to the link's start [m], negative inside, speed [m/s]).
        foe_signals: per conflict, the foe link's signal char ("" without a light).
        foe_limits: per conflict, the speed limit of the foe link's lane [m/s] (None: no limits known).

    Returns:
        dicts with ``ego_dist_m`` / ``ego_exit_m``: distance from the ego's front bumper to the
        start / end of the conflict area [m]; ``foe_dist_m`` / ``foe_exit_m``: the same for the
        foe's front bumper; ``foe_speed_mps``; ``ego_yields`` / ``foe_yields`` (:func:`gives_way`);
        ``foe_signal``: the foe's signal before it enters the junction ("" without a light or once
        inside); ``foe_speeding``: faster than :data:`SPEEDING_FACTOR` times its lane's limit.
    """
    out = []
    limits = foe_limits if foe_limits is not None else [math.inf] * len(conflicts)
    for c, link_users, foe_signal, limit in zip(conflicts, users, foe_signals, limits):
        for _, dist, speed in link_users:
            out.append({
                "ego_dist_m": entry_m + c.at_m, "ego_exit_m": entry_m + c.clear_m,
                "foe_dist_m": dist + c.foe_at_m, "foe_exit_m": dist + c.foe_clear_m, "foe_speed_mps": float(speed),
                "ego_yields": gives_way(signal, state, foe_signal, c.foe.state),
                "foe_yields": gives_way(foe_signal, c.foe.state, signal, state),
                "foe_signal": foe_signal if dist > 0.0 else "",
                "foe_speeding": bool(speed > SPEEDING_FACTOR * limit),
            })
    return tuple(out)


class PrivilegedScene:
    """The privileged fields of one vehicle's scene in one world (the SUMO queries go through ``sim``).

    Args:
        net / sim: the world's network and simulation.
        vehicle_id / vtype: the vehicle the scene is for and its type (footprint).
        fidelity: the world's fidelity.
        lane_path: the centreline the motion planner tracks for (lane, next edges) in continuous
            fidelity (:meth:`hbmp_bench.envs.drivers.ModelDriver.lane_path`), None in event fidelity.
    """

    def __init__(self, net: RoadNetwork, sim: SumoSim, vehicle_id: str, vtype: VehicleType, fidelity: str,
                 lane_path=None):
        self.net, self.sim, self.vehicle_id, self.vtype = net, sim, vehicle_id, vtype
        self.fidelity, self.lane_path = fidelity, lane_path
        self._path = functools.lru_cache(maxsize=256)(
            lambda lane, nxt, via, into: followed_path(net, lane, nxt, 10.0, LEADER_RANGE_M + 20.0, via=via, into=into))

    def fields(self, ego: VehicleState, followed_lane: str, next_edges: tuple[str, ...], actors: Actors,
               lights: list[LightAhead], junction_exit_m: float, into: tuple[frozenset[str], ...] = ()) -> dict:
        """The fields for the vehicle ``ego`` following ``followed_lane`` onto ``next_edges`` (into
        the route's lanes ``into`` there, see :func:`followed_path`), among ``actors``; the world
        measures along its route the ``lights`` ahead (nearest first) and ``junction_exit_m``."""
        lane = followed_lane or ego.lane
        into = tuple(into)
        link, entry = self._link_ahead(ego, followed_lane, next_edges, into)
        crossings = () if link is None else self._crossings(link, entry, actors)
        held = {p for c, waiting in crossings if c["signal"] and c["signal"] in RED + YELLOW for p in waiting}
        out = path_actors(self._path(lane, tuple(next_edges[:3]), link.via if link is not None else "", into[:3]), ego.xy,
                          self.vtype.length, self.vtype.width, actors.xy, actors.yaw, actors.speed, actors.length,
                          actors.width, actors.is_pedestrian, np.isin(actors.ids, list(held)) if held else None)
        out["lights_ahead"] = tuple((float(light.distance), light.state,
                                     self.sim.signal_schedule(light.tls, light.link_index))
                                    for light in lights if light.distance <= LIGHTS_RANGE_M)
        out["junction_exit_m"] = junction_exit_m
        out["junction_foes"] = () if link is None else self._junction_foes(link, entry)
        out["crossings"] = tuple(c for c, _ in crossings)
        out["fidelity"] = self.fidelity
        if self.lane_path is not None:
            out.update(self._lane_tracking(ego, lane, next_edges, into))
        return out

    def _front(self, ego: VehicleState) -> np.ndarray:
        return ego.xy + self.vtype.length / 2 * np.array([np.cos(ego.yaw), np.sin(ego.yaw)])

    def _link_ahead(self, ego: VehicleState, followed_lane: str, next_edges: tuple[str, ...],
                    into: tuple[frozenset[str], ...] = ()) -> tuple[Connection | None, float]:
        """The link from the followed lane onto the route's next edge (the junction ahead, or the
        one the vehicle is in) and the distance from the front bumper to its start [m] (negative
        inside); (None, nan) where there is none. Where several links lead there, in event
        fidelity the one SUMO drives the vehicle over (the one it is on, or the one it approaches);
        with the motion planner the one its centreline follows (into the route's lanes ``into``:
        ``RoadNetwork.follow``)."""
        if followed_lane not in self.net.lanes:
            return None, float("nan")
        lane = self.net.lane(followed_lane)
        nxt = next_edges[0] if next_edges else None
        links = [c for c in self.net.connections[lane.edge] if c.from_lane == followed_lane and c.to_edge == nxt]
        link = self._driven_link(ego, followed_lane, nxt, links, into) if len(links) > 1 else (links[0] if links else None)
        if link is None or len(self.net.link_shape(link)) < 2:
            return None, float("nan")
        ends, direction = stop_line_of(lane.shape, lane.width)
        front = self._front(ego)
        entry = float((ends[0] - front) @ direction)
        if entry <= 0.0:
            entry = -project_on_polyline(self.net.link_shape(link), front)[0]
        return link, entry

    def _driven_link(self, ego: VehicleState, followed_lane: str, nxt: str | None, links: list[Connection],
                     into: tuple[frozenset[str], ...]) -> Connection:
        """Of several ``links`` from the followed lane onto ``nxt``, the one the vehicle drives (see
        :meth:`_link_ahead`); the first where none matches."""
        if self.lane_path is not None:
            step = self.net.follow(followed_lane, nxt, into[0] if into else frozenset())
            return next((c for c in links if (c.via or c.to_lane) == step), links[0])
        on = ego.lane if ego.lane in self.net.internal_lanes else self.sim.next_junction_lane(self.vehicle_id)
        return next((c for c in links if c.via == on or on in self.net.link_lanes(c)), links[0])

    def _junction_foes(self, link: Connection, entry: float) -> tuple[dict, ...]:
        conflicts = self.net.link_conflicts(link)
        users = [tuple(u for u in self.sim.link_users(c.foe.from_lane, self.net.link_lanes(c.foe), FOE_RANGE_M)
                       if u[0] != self.vehicle_id) for c in conflicts]
        signals = [self.sim.light_state(c.foe.tls, c.foe.link_index) if c.foe.tls else "" for c in conflicts]
        signal = self.sim.light_state(link.tls, link.link_index) if link.tls else ""
        limits = [self.net.lane(c.foe.from_lane).speed for c in conflicts]
        return junction_foes(entry, signal, link.state, conflicts, users, signals, limits)

    def _crossings(self, link: Connection, entry: float, actors: Actors) -> tuple[tuple[dict, tuple[str, ...]], ...]:
        """(the scene's entry, the ids of the pedestrians waiting to step onto it) per crossing."""
        shape, out = self.net.link_shape(link), []
        for crossing, at, clear in self.net.link_crossings(link):
            point = point_along(shape, 0.5 * (at + clear))
            ids = tuple(p for p in self.sim.crossing_waiters(crossing.id, crossing.walkingareas) if p in actors.ids)
            waiting = [float(np.hypot(*(actors.xy[actors.ids.index(p)] - point))) for p in ids]
            out.append(({"ego_dist_m": entry + at, "ego_exit_m": entry + clear,
                         "signal": self.sim.light_state(crossing.tls, crossing.link_index) if crossing.tls else "",
                         "waiting_m": tuple(sorted(waiting))}, ids))
        return tuple(out)

    def _lane_tracking(self, ego: VehicleState, lane: str, next_edges: tuple[str, ...],
                       into: tuple[frozenset[str], ...] = ()) -> dict:
        path = self.lane_path(lane, tuple(next_edges), into)
        s, e, theta, _ = path.project(ego.xy, ego.yaw)
        ahead = np.arange(s, s + max(3.0 * ego.speed, 5.0) + 10.0, 1.0)
        return {"lane_error_m": float(e), "heading_error_rad": float(theta),
                "curvature_ahead": float(np.max(np.abs(path.point_at(ahead)[3])))}
