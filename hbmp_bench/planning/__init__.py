"""Behavior-conditioned motion planning of HBMP (numpy, simulator-agnostic).

Modules:
    frame      -- :class:`Path`: curvilinear frame on a lane centerline.
    control    -- lane-converging control law and linear speed profile.
    behaviors  -- :class:`Behavior` enum and the reference-speed rule.
    state      -- :class:`VehicleState`, :class:`Obstacles`.
    planner    -- sampling planner :func:`plan` with the paper's costs.
    rollout    -- its closed-loop roll-out, compiled with numba.
    obstacle_kernels -- its obstacle cost and collision check, compiled with numba.
    plan_kernel -- one planning call (samples, roll-out, obstacle stage) as one compiled kernel.
    vehicle    -- kinematic bicycle model with actuator limits.
    tracking   -- PID speed + pure-pursuit steering tracker.
    tracking_kernel -- the tracker's look-ahead point and speed look-up, compiled with numba.
    executor   -- :class:`BehaviorExecutor` (replan + track until the behavior ends).
    sim        -- SUMO-free closed loop used by tests.

Units: metres, seconds, radians, m/s; yaw counter-clockwise from +x, lateral error
positive to the left.
"""

from .behaviors import Behavior, BehaviorConfig, reference_speed
from .control import control_law, linear_speed_profile, omega_limit
from .executor import (BehaviorExecutor, BehaviorOutcome, ExecutorConfig, ReferencePaths,
                       reward_from_cost, target_path)
from .frame import Path, round_corners, wrap_angle
from .planner import COST_NAMES, PlannerConfig, PlanningProblem, PlanResult, instant_costs, plan
from .sim import Rollout, simulate_behavior
from .state import Obstacles, VehicleState
from .tracking import PID, TrackerConfig, TrajectoryTracker
from .vehicle import Control, VehicleParams, step

__all__ = [
    "Behavior", "BehaviorConfig", "reference_speed",
    "control_law", "linear_speed_profile", "omega_limit",
    "BehaviorExecutor", "BehaviorOutcome", "ExecutorConfig", "ReferencePaths",
    "reward_from_cost", "target_path",
    "Path", "round_corners", "wrap_angle",
    "COST_NAMES", "PlannerConfig", "PlanningProblem", "PlanResult", "instant_costs", "plan",
    "Rollout", "simulate_behavior",
    "Obstacles", "VehicleState",
    "PID", "TrackerConfig", "TrajectoryTracker",
    "Control", "VehicleParams", "step",
]
