"""SUMO-free closed loop: executor + bicycle model + constant-velocity obstacles.

Used by the tests and handy for checking planner settings without a simulator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .behaviors import Behavior
from .executor import BehaviorExecutor, BehaviorOutcome, ReferencePaths
from .state import Obstacles, VehicleState
from .vehicle import VehicleParams, step

__all__ = ["Rollout", "simulate_behavior"]


@dataclass(frozen=True, eq=False)
class Rollout:
    """Result of :func:`simulate_behavior`.

    Attributes:
        outcome: the executor's summary.
        states: (N + 1, 5) ``[x, y, yaw, v, steer]`` of the ego, one row per step [SI].
        final: last ego state.
        obstacles: obstacles at the final time.
    """

    outcome: BehaviorOutcome
    states: np.ndarray
    final: VehicleState
    obstacles: Obstacles


def _advance(obs: Obstacles, dt: float) -> Obstacles:
    if len(obs) == 0:
        return obs
    return Obstacles(obs.x + obs.v * np.cos(obs.yaw) * dt, obs.y + obs.v * np.sin(obs.yaw) * dt,
                     obs.yaw, obs.v, obs.length, obs.width)


def simulate_behavior(
    executor: BehaviorExecutor,
    behavior: Behavior | int,
    ego: VehicleState,
    refs: ReferencePaths | tuple,
    speed_limit: float,
    obstacles: Obstacles | None = None,
    vehicle: VehicleParams | None = None,
    max_steps: int = 1000,
) -> Rollout:
    """Run one behavior to completion with the kinematic bicycle model.

    Obstacles move at constant velocity along their heading. ``vehicle`` defaults to the
    executor tracker's :class:`.vehicle.VehicleParams`.
    """
    vehicle = executor.tracker.vehicle if vehicle is None else vehicle
    obs = Obstacles.empty() if obstacles is None else obstacles
    dt = executor.cfg.dt
    executor.start(behavior, ego, refs, speed_limit)
    rows = [[ego.x, ego.y, ego.yaw, ego.v, ego.steer]]
    for _ in range(max_steps):  # loop over time steps of one vehicle
        control, _ = executor.step(ego, obs)
        if executor.done:
            break
        ego = step(ego, control, dt, vehicle)
        obs = _advance(obs, dt)
        rows.append([ego.x, ego.y, ego.yaw, ego.v, ego.steer])
    return Rollout(executor.outcome(), np.array(rows), ego, obs)
