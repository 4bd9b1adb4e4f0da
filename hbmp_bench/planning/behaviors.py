"""The five HBMP behaviors and their reference speed.

Paper: "When speed_up and speed_down are made, a reference linear velocity v_ref is
assigned by increasing or decreasing a percentage of the current feedback velocity. For
change_left, change_right, and keep, v_ref keeps the same to the current velocity."

Here the speed step is ``max(speed_change_frac * |v|, min_speed_step)`` so that a
``speed_up`` from standstill (where a percentage is 0) still moves the car; the result is
clipped to ``[0, speed_limit]``. ``keep`` uses ``v_ref = v_current`` unchanged (no creep,
no clipping to the limit: the paper keeps the current velocity; a stopped car stays
stopped until the behavior planner chooses ``speed_up``). Lane changes keep the current
velocity too, but at least ``min_lane_change_speed`` (capped by the limit): a car cannot
move sideways at standstill, so a lane change chosen while stopped would never complete
(the event stage's SUMO lane change is instantaneous and needs no speed).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

__all__ = ["Behavior", "BehaviorConfig", "reference_speed"]


class Behavior(IntEnum):
    """High-level behavior ``b_k`` in the paper's order."""

    SPEED_UP = 0
    SPEED_DOWN = 1
    CHANGE_LEFT = 2
    CHANGE_RIGHT = 3
    KEEP = 4


@dataclass(frozen=True)
class BehaviorConfig:
    """Reference-speed rule.

    Attributes:
        speed_change_frac: fraction of the current speed added / removed by speed_up /
            speed_down (default 0.2 = 20 %).
        min_speed_step: minimum speed step [m/s] (default 2.0; matters below
            ``min_speed_step / speed_change_frac`` = 10 m/s, e.g. from standstill).
    """

    speed_change_frac: float = 0.2
    min_speed_step: float = 2.0
    min_lane_change_speed: float = 2.0

    def __post_init__(self):
        if not 0.0 < self.speed_change_frac < 1.0:
            raise ValueError(f"speed_change_frac must be in (0, 1), got {self.speed_change_frac!r}")
        if not self.min_speed_step >= 0.0:
            raise ValueError(f"min_speed_step must be >= 0 [m/s], got {self.min_speed_step!r}")
        if not self.min_lane_change_speed >= 0.0:
            raise ValueError(f"min_lane_change_speed must be >= 0 [m/s], got {self.min_lane_change_speed!r}")


def reference_speed(
    behavior: Behavior | int,
    v_current: float,
    speed_limit: float,
    cfg: BehaviorConfig = BehaviorConfig(),
) -> float:
    """Reference speed ``v_ref`` [m/s] of a behavior.

    Args:
        behavior: a :class:`Behavior` (or its int value).
        v_current: current (feedback) speed [m/s].
        speed_limit: current lane speed limit [m/s] (> 0).
        cfg: step sizes.

    Returns:
        ``speed_up``: ``min(v + step, speed_limit)``; ``speed_down``: ``max(v - step, 0)``
        (also at most ``speed_limit``); change_left / change_right:
        ``max(v_current, min(min_lane_change_speed, speed_limit))``; keep: ``v_current``;
        ``step = max(speed_change_frac * |v|, min_speed_step)``.
    """
    b = Behavior(int(behavior))
    if not speed_limit > 0:
        raise ValueError(f"speed_limit must be > 0 [m/s], got {speed_limit!r}")
    v = float(v_current)
    if v != v:
        raise ValueError("v_current is NaN")
    step = max(cfg.speed_change_frac * abs(v), cfg.min_speed_step)
    if b == Behavior.SPEED_UP:
        return float(min(max(v + step, 0.0), speed_limit))
    if b == Behavior.SPEED_DOWN:
        return float(min(max(v - step, 0.0), speed_limit))
    if b in (Behavior.CHANGE_LEFT, Behavior.CHANGE_RIGHT):
        return max(v, min(cfg.min_lane_change_speed, speed_limit))
    return v
