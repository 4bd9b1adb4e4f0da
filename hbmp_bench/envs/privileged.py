"""Privileged quantities of ``info["scene"]``: what the rule-based expert reads besides M_t and R_t.

A learned agent sees only M_t and R_t; the expert (:mod:`hbmp_bench.agents.expert`), a
demonstrator, may read the simulator's state. The fields this module measures (geometry only,
numpy) are listed in :func:`path_actors`; the world adds the ones it reads from SUMO (see
:meth:`hbmp_bench.envs.world.DrivingWorld` ``_observe``):

  lights_ahead     the traffic lights on the route within ``LIGHTS_RANGE_M``, nearest first (also
                   beyond junctions without lights, unlike R_t's l_g/l_y/l_r and ``light``): one
                   (distance from the front bumper to the stop line [m], signal char, schedule) per
                   light, the schedule ((0, char now), (seconds until the next change, char), ...)
                   of its link for the next minute
  junction_exit_m  distance from the front bumper to the end of the junction the route crosses
                   next (or is crossing) [m]; inf after the last junction
  junction_foes    the vehicles on or before (up to ``FOE_RANGE_M``) the links that conflict with
                   the ego's link through the junction ahead (or the one it is in), see
                   :func:`junction_foes`
  crossings        the pedestrian crossings the ego's link through the junction ahead (or the one
                   it is in) passes over: one dict per crossing with ``ego_dist_m`` / ``ego_exit_m``
                   (ego front to the start / end of the stretch of its path over the crossing [m]),
                   ``signal`` (the pedestrians' signal char, "" without a light) and ``waiting_m``
                   (distance [m] from each pedestrian waiting to step onto it to that stretch)
  fidelity         the world's fidelity (``event`` or ``continuous``)
  lane_error_m, heading_error_rad, curvature_ahead
                   continuous fidelity only: the ego's lateral offset [m] and heading error [rad]
                   from the centreline the motion planner tracks, and that centreline's sharpest
                   curvature [1/m] over the next 3 s; a behavior begun with small errors on a
                   straight stretch ends after about its minimum duration, otherwise it may run to
                   the planner's maximum (8 s)
"""

from __future__ import annotations

import numpy as np

from hbmp_bench.planning.frame import Path

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
                is_pedestrian: np.ndarray) -> dict:
    """The actors near the followed lane's centreline ``path``, measured along it.

    Args:
        path: the centreline the ego follows (its lane, through the junctions of its route).
        ego_xy: (2,) ego footprint centre [m]; ego_length / ego_width: its footprint [m].
        xy, yaw, speed, length, width, is_pedestrian: (K,) the other actors (centres [m],
            headings [rad], speeds [m/s], footprints [m]).

    Returns:
        ``leader_gap_m``: free distance from the ego's front bumper to the nearest actor ahead
        whose footprint lies in the ego's corridor (vehicle or pedestrian), inf if none within
        ``LEADER_RANGE_M``; ``leader_speed_mps``: that actor's speed along the path [m/s] (0 if
        none; negative when it comes towards the ego); ``pedestrians``: ((s, d, v_s, v_d), ...) for
        every pedestrian ahead within ``PEDESTRIAN_RANGE_M`` and ``PEDESTRIAN_LATERAL_M``: its
        distance along the path from the ego's front bumper [m], signed lateral offset (left
        positive) [m] and velocity along / across the path (left positive) [m/s], nearest first.
    """
    out = {"leader_gap_m": float("inf"), "leader_speed_mps": 0.0, "pedestrians": ()}
    if len(xy) == 0:
        return out
    s_ego, _ = path.frenet(ego_xy)
    front = float(s_ego) + ego_length / 2
    near = np.hypot(*(xy - ego_xy).T) < LEADER_RANGE_M + ego_length + 10.0
    if not near.any():
        return out
    idx = np.nonzero(near)[0]
    s, d, theta, _ = path.project(xy[idx], yaw[idx])
    s, d, theta = np.atleast_1d(s), np.atleast_1d(d), np.atleast_1d(theta)
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
    out["pedestrians"] = tuple((float(a), float(b), float(e), float(f)) for a, b, e, f in
                               zip((s[ped] - front)[order], d[ped][order], v_s[ped][order], v_d[ped][order]))
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


def junction_foes(entry_m: float, signal: str, state: str, conflicts, users, foe_signals) -> tuple[dict, ...]:
    """The ``junction_foes`` of the scene: one dict per vehicle on a conflicting link.

    Args:
        entry_m: distance from the ego's front bumper to the start of its link [m] (negative inside).
        signal / state: the ego link's signal char ("" without a light) and static state.
        conflicts: the :class:`hbmp_bench.maps.roadnet.LinkConflict` s of the ego's link.
        users: per conflict, the vehicles on or before the foe link: (id, distance from the
            front bumper to the link's start [m], negative inside, speed [m/s]).
        foe_signals: per conflict, the foe link's signal char ("" without a light).

    Returns:
        dicts with ``ego_dist_m`` / ``ego_exit_m``: distance from the ego's front bumper to the
        start / end of the conflict area [m]; ``foe_dist_m`` / ``foe_exit_m``: the same for the
        foe's front bumper; ``foe_speed_mps``; ``ego_yields`` / ``foe_yields`` (:func:`gives_way`);
        ``foe_signal``: the foe's signal before it enters the junction ("" without a light or once
        inside).
    """
    out = []
    for c, link_users, foe_signal in zip(conflicts, users, foe_signals):
        for _, dist, speed in link_users:
            out.append({
                "ego_dist_m": entry_m + c.at_m, "ego_exit_m": entry_m + c.clear_m,
                "foe_dist_m": dist + c.foe_at_m, "foe_exit_m": dist + c.foe_clear_m, "foe_speed_mps": float(speed),
                "ego_yields": gives_way(signal, state, foe_signal, c.foe.state),
                "foe_yields": gives_way(foe_signal, c.foe.state, signal, state),
                "foe_signal": foe_signal if dist > 0.0 else "",
            })
    return tuple(out)
