"""The scene: R_t's quantities in metres and m/s, and for a privileged reader (the rule-based
expert, a demonstrator, in a world with ``WorldConfig.privileged``) what it sees besides M_t and
R_t. Built typed by the vehicle (:class:`~hbmp_bench.envs.vehicle.ControlledVehicle`), handed to
agents as a plain dict at the info boundary (``info["scene"] = scene.to_dict()``: data only, it
crosses the evaluation's agent channel), where the fields a vehicle does not have are left out.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass


NON_PRIVILEGED_FIELDS = ("speed_mps", "speed_limit_mps", "in_junction", "route_lane_offset", "stop_distance_m",
                         "lane_pos_m", "light", "turn_ahead", "goal_distance_m")
"""The scene fields every world fills (R_t's quantities; the ego's goal distance)."""


@dataclass(frozen=True)
class Scene:
    """One vehicle's scene now. Distances [m], speeds [m/s], angles [rad], curvature [1/m].

    Every controlled vehicle (R_t's inputs, :func:`hbmp_bench.envs.observation.road_profile`):
        speed_mps, speed_limit_mps: its speed and its lane's limit.
        in_junction: on a junction lane.
        route_lane_offset: lanes to the nearest lane that continues the route (+ left), 0 in one.
        stop_distance_m: to the end of its lane, or to the light ahead's stop line (inf: none).
        lane_pos_m: front bumper's position on its lane.
        light: signal char of the light at the end of its lane ("" none; in a junction the next one).
        turn_ahead: SUMO direction of the route's next link (``s``, ``l``, ``r``, ...; "" none).

    The ego only (None elsewhere):
        goal_distance_m: straight-line distance from its centre to the goal. Not privileged: it
            follows from the ego's own pose and the episode's goal, no other actor's state and
            nothing of the future.

    The ego in a world with ``WorldConfig.privileged`` only (see :mod:`hbmp_bench.envs.privileged`
    for each): leader_gap_m, leader_speed_mps, pedestrians, lights_ahead, route_lane_light,
    junction_exit_m, junction_foes, crossings, fidelity; and in continuous fidelity
    lane_error_m, heading_error_rad, curvature_ahead.
    """

    speed_mps: float
    speed_limit_mps: float
    in_junction: bool
    route_lane_offset: int
    stop_distance_m: float
    lane_pos_m: float
    light: str
    turn_ahead: str
    goal_distance_m: float | None = None
    leader_gap_m: float | None = None
    leader_speed_mps: float | None = None
    pedestrians: tuple | None = None
    lights_ahead: tuple | None = None
    route_lane_light: tuple | None = None
    junction_exit_m: float | None = None
    junction_foes: tuple | None = None
    crossings: tuple | None = None
    fidelity: str | None = None
    lane_error_m: float | None = None
    heading_error_rad: float | None = None
    curvature_ahead: float | None = None

    def to_dict(self) -> dict:
        """``info["scene"]``: the fields this vehicle has (None ones left out)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if getattr(self, f.name) is not None}
