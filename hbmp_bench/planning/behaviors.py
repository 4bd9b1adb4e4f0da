"""The five HBMP behaviors and their reference speed.

Paper: "When speed_up and speed_down are made, a reference linear velocity v_ref is
assigned by increasing or decreasing a percentage of the current feedback velocity. For
change_left, change_right, and keep, v_ref keeps the same to the current velocity."

Here each speed behavior steps ``v_ref`` from the current speed ``v`` [m/s]::

    speed_up:   v_ref = min(v + max(speed_up_frac   |v|, speed_up_min_step),   speed_limit)
    speed_down: v_ref = max(v - max(speed_down_frac |v|, speed_down_min_step), 0)

(``speed_down`` is also capped at the limit). The percentage is the paper's; the minimum
step makes a ``speed_up`` from standstill (where a percentage is 0) move the car and a
``speed_down`` at low speed reach a stop.

Deviation -- the two steps differ (defaults: speed_up 20 % / 2 m/s, speed_down 35 % / 3.5 m/s).
The paper gives neither value; until this change both were 20 % / 2 m/s. In the continuous
fidelity a behavior lasts until the planner has realised ``v_ref`` and at least
:attr:`.executor.ExecutorConfig.min_duration` (1 s), so a chain of speed_down behaviors
brakes at about ``step / 1 s``: with 20 % / 2 m/s ~2 m/s^2, and a stop from 50 km/h took 43 m
after the first speed_down -- 57 m counting the 1 s behavior running before it, which cannot
be interrupted. A lawful driver stops for a yellow within ``v * 1 s + v^2 / (2 * 3 m/s^2)``
(46 m from 13.9 m/s, reaction included); farther than that and some reds cannot be avoided.
A speed_down step of at least ``decel * min_duration`` (3 m/s with the planner's 3 m/s^2)
keeps the planner braking along its speed profile for the whole behavior (about 3.7 m/s^2
with the tracking): with 35 % / 3.5 m/s four speed_down decisions stop the ego from 50 km/h
(speed 13.9, 9.2, 6.0, 2.7 m/s at the decisions) in 28 m, 42 m with the 1 s latency (SUMO,
Town01; ``hbmp_bench.envs.stopping``). In the event fidelity SUMO brakes at the ego type's
deceleration whatever the step (21 m with 0.1 s decisions; with 1 s decisions 23 m instead of
38 m). Larger fractions stop barely sooner (50 %: 27 m) but make the paper's c_velocity
prefer the planner's full-brake sample (6 m/s^2) to its comfortable profile when the step is
large (50 % above 22 m/s, 40 % above 27.6 m/s, 35 % never below 30 m/s). ``speed_up`` keeps
20 % / 2 m/s: acceleration stays gentle and a chain of speed_up passes through closely spaced
speeds. Unchanged: the planner
realises ``v_ref`` with the paper's linear speed profile at its own acceleration /
deceleration (:class:`.planner.PlannerConfig`), and the behavior duration and finish
condition are those of :mod:`.executor`.

``keep`` uses ``v_ref = v_current`` unchanged (no creep, no clipping to the limit: the paper
keeps the current velocity; a stopped car stays stopped until the behavior planner chooses
``speed_up``). Lane changes keep the current velocity too, but at least
``min_lane_change_speed`` (capped by the limit): a car cannot move sideways at standstill, so
a lane change chosen while stopped would never complete (the event stage's SUMO lane change
is instantaneous and needs no speed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from hbmp_bench.errors import ConfigError
from hbmp_bench.vocabulary import BEHAVIORS

__all__ = ["BEHAVIORS", "Behavior", "BehaviorConfig", "reference_speed"]


class Behavior(IntEnum):
    """High-level behavior ``b_k`` in the paper's order (``BEHAVIORS[b]``, from the vocabulary, names ``b``)."""

    SPEED_UP = 0
    SPEED_DOWN = 1
    CHANGE_LEFT = 2
    CHANGE_RIGHT = 3
    KEEP = 4


@dataclass(frozen=True)
class BehaviorConfig:
    """Reference-speed rule (see the module docstring for why the two steps differ).

    Attributes:
        speed_up_frac: fraction of the current speed added by speed_up (default 0.2 = 20 %).
        speed_up_min_step: least speed step of speed_up [m/s] (default 2.0; matters below
            ``speed_up_min_step / speed_up_frac`` = 10 m/s, e.g. from standstill).
        speed_down_frac: fraction of the current speed removed by speed_down (default 0.35 =
            35 %; 1 = every speed_down asks for a stop).
        speed_down_min_step: least speed step of speed_down [m/s] (default 3.5; matters below
            10 m/s and brings a chain of speed_down to standstill).
        min_lane_change_speed: least v_ref of change_left / change_right [m/s] (capped by the
            speed limit).
    """

    speed_up_frac: float = 0.2
    speed_up_min_step: float = 2.0
    speed_down_frac: float = 0.35
    speed_down_min_step: float = 3.5
    min_lane_change_speed: float = 2.0

    def __post_init__(self):
        if not 0.0 < self.speed_up_frac < 1.0:
            raise ConfigError(f"speed_up_frac must be in (0, 1), got {self.speed_up_frac!r}")
        if not 0.0 < self.speed_down_frac <= 1.0:
            raise ConfigError(f"speed_down_frac must be in (0, 1], got {self.speed_down_frac!r}")
        for name in ("speed_up_min_step", "speed_down_min_step", "min_lane_change_speed"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigError(f"{name} must be finite and >= 0 [m/s], got {value!r}")

    def speed_step(self, behavior: Behavior | int, v_current: float) -> float:
        """Size [m/s] of the v_ref step of ``speed_up`` / ``speed_down`` at ``v_current`` [m/s]
        (0 for the other behaviors)."""
        b = Behavior(int(behavior))
        if b == Behavior.SPEED_UP:
            return max(self.speed_up_frac * abs(v_current), self.speed_up_min_step)
        if b == Behavior.SPEED_DOWN:
            return max(self.speed_down_frac * abs(v_current), self.speed_down_min_step)
        return 0.0


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
        (also at most ``speed_limit``), ``step`` = :meth:`BehaviorConfig.speed_step`;
        change_left / change_right: ``max(v_current, min(min_lane_change_speed, speed_limit))``;
        keep: ``v_current``.
    """
    b = Behavior(int(behavior))
    if not speed_limit > 0:
        raise ValueError(f"speed_limit must be > 0 [m/s], got {speed_limit!r}")
    v = float(v_current)
    if v != v:
        raise ValueError("v_current is NaN")
    if b == Behavior.SPEED_UP:
        return float(min(max(v + cfg.speed_step(b, v), 0.0), speed_limit))
    if b == Behavior.SPEED_DOWN:
        return float(min(max(v - cfg.speed_step(b, v), 0.0), speed_limit))
    if b in (Behavior.CHANGE_LEFT, Behavior.CHANGE_RIGHT):
        return max(v, min(cfg.min_lane_change_speed, speed_limit))
    return v
