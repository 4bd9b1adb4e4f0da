"""Kinematic bicycle model with actuator limits.

State: :class:`.state.VehicleState` ``(x, y, yaw, v, steer)`` referred to the footprint
centre (the centre of gravity, ``rear_to_cg`` ahead of the rear axle). Inputs:
:class:`Control` ``(steer, throttle, brake)`` with ``steer`` in ``[-1, 1]`` (fraction of
``max_steer``; positive = LEFT, counter-clockwise, like the yaw convention), ``throttle``
and ``brake`` in ``[0, 1]``.

Dynamics (integrated with explicit Euler sub-steps of at most ``max_substep``)::

    delta     -> steer * max_steer at most max_steer_rate [rad/s]
    beta      = atan(rear_to_cg / wheelbase * tan(delta))     (slip angle at the CG)
    x'        = v cos(yaw + beta),  y' = v sin(yaw + beta)
    yaw'      = v cos(beta) tan(delta) / wheelbase
    v'        = throttle * max_accel - brake * max_decel        (v clipped to [0, max_speed])
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .state import VehicleState

from hbmp_bench.errors import ConfigError

__all__ = ["VehicleParams", "Control", "step"]


@dataclass(frozen=True)
class VehicleParams:
    """Vehicle geometry and actuator limits.

    Attributes:
        wheelbase: axle distance [m].
        rear_to_cg: rear axle to reference point (footprint centre) [m], ``<= wheelbase``.
        max_steer: front-wheel steering limit [rad].
        max_steer_rate: front-wheel steering rate limit [rad/s].
        max_accel: acceleration at full throttle [m/s^2].
        max_decel: deceleration at full brake [m/s^2].
        max_speed: speed cap [m/s].
        max_substep: largest integration sub-step [s].
    """

    wheelbase: float = 2.8
    rear_to_cg: float = 1.4
    max_steer: float = 0.6
    max_steer_rate: float = 1.2
    max_accel: float = 3.0
    max_decel: float = 8.0
    max_speed: float = 50.0
    max_substep: float = 0.02

    def __post_init__(self):
        for name in ("wheelbase", "max_steer", "max_steer_rate", "max_accel", "max_decel",
                     "max_speed", "max_substep"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"VehicleParams.{name} must be finite and > 0, got {v!r}")
        if not 0 <= self.rear_to_cg <= self.wheelbase:
            raise ConfigError(
                f"VehicleParams.rear_to_cg must be in [0, wheelbase], got {self.rear_to_cg!r}")
        if self.max_steer >= math.pi / 2:
            raise ConfigError(
                f"VehicleParams.max_steer must be < pi/2 [rad], got {self.max_steer!r}")

    @property
    def max_curvature(self) -> float:
        """Path curvature at full steer (rear-axle path) [1/m]."""
        return math.tan(self.max_steer) / self.wheelbase


@dataclass(frozen=True)
class Control:
    """Actuator command.

    Attributes:
        steer: normalised steering in ``[-1, 1]`` (positive = left).
        throttle: ``[0, 1]``.
        brake: ``[0, 1]``.
    """

    steer: float = 0.0
    throttle: float = 0.0
    brake: float = 0.0

    def __post_init__(self):
        if not -1.0 <= self.steer <= 1.0:
            raise ConfigError(f"Control.steer must be in [-1, 1], got {self.steer!r}")
        if not 0.0 <= self.throttle <= 1.0:
            raise ConfigError(f"Control.throttle must be in [0, 1], got {self.throttle!r}")
        if not 0.0 <= self.brake <= 1.0:
            raise ConfigError(f"Control.brake must be in [0, 1], got {self.brake!r}")


def step(state: VehicleState, control: Control, dt: float,
         params: VehicleParams = VehicleParams()) -> VehicleState:
    """Advance the bicycle model by ``dt`` [s] under a constant ``control``."""
    if not (math.isfinite(dt) and dt >= 0):
        raise ValueError(f"dt must be finite and >= 0 [s], got {dt!r}")
    n = max(1, math.ceil(dt / params.max_substep - 1e-9))
    h = dt / n
    x, y, yaw, v, delta = state.x, state.y, state.yaw, state.v, state.steer
    target = control.steer * params.max_steer
    dmax = params.max_steer_rate * h
    acc = control.throttle * params.max_accel - control.brake * params.max_decel
    lr, L = params.rear_to_cg, params.wheelbase
    for _ in range(n):  # loop over integration sub-steps of one vehicle
        delta += min(max(target - delta, -dmax), dmax)
        delta = min(max(delta, -params.max_steer), params.max_steer)
        tan_d = math.tan(delta)
        beta = math.atan(lr / L * tan_d)
        x += v * math.cos(yaw + beta) * h
        y += v * math.sin(yaw + beta) * h
        yaw += v * math.cos(beta) * tan_d / L * h
        v = min(max(v + acc * h, 0.0), params.max_speed)
    yaw = math.atan2(math.sin(yaw), math.cos(yaw))
    return VehicleState(x=x, y=y, yaw=yaw, v=v, steer=delta)
