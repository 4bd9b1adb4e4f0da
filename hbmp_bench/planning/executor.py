"""Execution of one behavior: replanning + tracking until the behavior finishes.

:class:`BehaviorExecutor` knows nothing about the simulator. The environment drives it::

    ex = BehaviorExecutor()
    ex.start(behavior, ego, ReferencePaths(left, current, right), speed_limit)
    while True:
        control, plan = ex.step(ego, obstacles)   # every 0.1 s
        if ex.done:                                # `ego` met the finish condition
            break                                  # (or max_duration elapsed)
        ego = simulator.apply(control, 0.1)        # advance the world by dt
    r_k = ex.reward()                              # lambda(c~_total) = -scale * c~_total

* Target lane: ``change_left`` -> ``left``, ``change_right`` -> ``right``, others ->
  ``current``. A lane change towards a missing lane (``None``) becomes ``keep``
  (paper: "If the behavior conflicts with R_t, keep is made instead").
* ``v_ref`` is fixed at :meth:`~BehaviorExecutor.start` by
  :func:`.behaviors.reference_speed` from the speed at decision time.
* Replanning every ``replan_every`` steps (default every step: 10 Hz at ``dt = 0.1`` s);
  tracking every step (:class:`.tracking.TrajectoryTracker`).
* Finish, checked at the start of a step after at least ``min_duration`` [s] of execution:
  a lane change when the incoming ego state has ``|e| < e_thresh`` and ``|theta_e| <
  theta_thresh`` on the target lane (the paper's rule); speed_up / speed_down when ``|v -
  v_ref| < v_thresh`` (``v_ref`` capped for curves by the latest plan, see
  :func:`.planner.curve_speed_cap`); keep at once. Otherwise when its longest run has elapsed
  (reason ``"timeout"``): ``max_duration`` [s] for a lane change, ``lane_keeping_max_duration``
  [s] for the others.
* Deviation: the paper ends every behavior on the lane condition. For a behavior that stays in
  its lane the ego is normally on that lane already, so the condition holds at once there; in a
  bend, a junction turn or a swerve around an obstacle it only measures tracking lag, and waiting
  for it left the behavior layer blind for up to 8 s (a speed_down begun 31 m before a red line
  ran 4.6 s and crossed it; another plateaued at its v_ref for a second waiting for the lane and
  crossed). Here such behaviors end on their speed alone, after 1 to 2 s, so a chain of
  speed_down brakes continuously and decides about once a second everywhere; the motion is
  unchanged (the next behavior plans on the same lane).
* ``c~_total`` of the executed trajectory = the MEAN of the chosen sample's ``c_total``
  over the replans whose control was executed (the final, finishing step is not counted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .behaviors import Behavior, BehaviorConfig, reference_speed
from .frame import Path
from .planner import NO_CORRIDOR, PlannerConfig, PlanningProblem, PlanResult, plan
from .state import Obstacles, VehicleState
from .tracking import TrackerConfig, TrajectoryTracker
from .vehicle import Control, VehicleParams

from hbmp_bench.errors import ConfigError

__all__ = ["ExecutorConfig", "ReferencePaths", "BehaviorOutcome", "BehaviorExecutor",
           "reward_from_cost", "target_path"]


def reward_from_cost(c_total, scale: float = 1.0):
    """Behavior reward ``r_k = lambda(c~_total) = -scale * c~_total`` (scalar or array)."""
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be finite and > 0, got {scale!r}")
    return -scale * (np.asarray(c_total, dtype=float) if np.ndim(c_total) else float(c_total))


class ReferencePaths(NamedTuple):
    """Centerlines of the left, current and right lane (left / right may be ``None``), and the road
    beside the current one: ``corridor`` as :class:`.planner.PlanningProblem` takes it, used while the
    ego keeps its lane (default: no bounds)."""

    left: Path | None
    current: Path
    right: Path | None
    corridor: tuple[float, float, float] = NO_CORRIDOR

    @property
    def paths(self) -> tuple[Path | None, Path, Path | None]:
        """(left, current, right)."""
        return self.left, self.current, self.right


def target_path(behavior: Behavior | int, refs: ReferencePaths) -> tuple[Behavior, Path]:
    """Effective behavior and its reference path (missing lane -> ``KEEP`` on current)."""
    b = Behavior(int(behavior))
    if b == Behavior.CHANGE_LEFT:
        return (b, refs.left) if refs.left is not None else (Behavior.KEEP, refs.current)
    if b == Behavior.CHANGE_RIGHT:
        return (b, refs.right) if refs.right is not None else (Behavior.KEEP, refs.current)
    return b, refs.current


@dataclass(frozen=True)
class ExecutorConfig:
    """Timing and finish thresholds.

    Attributes:
        dt: control / tracking period [s].
        replan_every: replan every this many steps (1 -> 1/dt Hz).
        e_thresh: lateral-error threshold of a lane change [m].
        theta_thresh: heading-error threshold of a lane change [rad].
        v_thresh: speed-error threshold of speed_up / speed_down [m/s].
        min_duration: a behavior lasts at least this long [s] (decisions ~1 Hz).
        max_duration: a lane change is stopped after this long [s].
        lane_keeping_max_duration: speed_up, speed_down and keep are stopped after this long [s].
        reward_scale: the scale of the paper's λ (:func:`reward_from_cost`, used by
            :meth:`BehaviorExecutor.reward` and by the flat baseline's r_t). The paper gives λ only as
            "a mapping with negative scaling"; with episodes that end at the first violation the scale
            decides what PPO learns, since a car standing still costs c_dist = 1 per decision (about
            one a second). Too large, and waiting through a red costs more than running it: at 1 (a 50 s
            red: −50 against −10) PPO learnt to run red lights (42 → 57 → 67 red-light ends per 100
            training episodes, goals 49 → 32 → 29). Too small, and standing still is free: at 0.01 the
            PPO policy's training success rose (57 → 88 %) but its most likely behavior stood still, and
            greedily it timed out in 8 of 15 Town03 Navigation episodes (a timeout 300 decisions ahead is
            worth −50 · 0.99^300 = −2.5 now). 0.25 keeps both apart: waiting through the towns' longest
            red (57.4 s) costs 14, less than any violation that ends an episode (−51, with the overtime's
            −50: :data:`hbmp_bench.metrics.episode.GOAL_UNREACHABLE`), and standing still for good costs
            0.25 / (1 − 0.99) = 25, more than a red light's own −10. A test holds both bounds.
    """

    dt: float = 0.1
    replan_every: int = 1
    e_thresh: float = 0.3
    theta_thresh: float = 0.05
    v_thresh: float = 0.5
    min_duration: float = 1.0
    max_duration: float = 8.0
    lane_keeping_max_duration: float = 2.0
    reward_scale: float = 0.25

    def __post_init__(self):
        for name in ("dt", "e_thresh", "theta_thresh", "v_thresh", "max_duration", "lane_keeping_max_duration",
                     "reward_scale"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"ExecutorConfig.{name} must be finite and > 0, got {v!r}")
        if not (math.isfinite(self.min_duration)
                and 0 <= self.min_duration <= min(self.max_duration, self.lane_keeping_max_duration)):
            raise ConfigError("ExecutorConfig.min_duration must be in [0, min(max_duration, lane_keeping_max_duration)]")
        r = self.replan_every
        if not isinstance(r, (int, np.integer)) or isinstance(r, bool) or r < 1:
            raise ConfigError(f"ExecutorConfig.replan_every must be an int >= 1, got {r!r}")


@dataclass(frozen=True)
class BehaviorOutcome:
    """Summary of one executed behavior.

    Attributes:
        requested: behavior asked for.
        behavior: behavior executed (``KEEP`` when the requested lane is missing).
        v_ref: reference speed [m/s].
        duration: executed time [s] (``n_steps * dt``).
        n_steps: executed control steps.
        reason: ``"converged"``, ``"timeout"`` or ``"running"``.
        c_total: ``c~_total`` (mean chosen ``c_total`` over executed replans; 0 if none).
        c_terms: (3,) mean ``[c_velocity, c_dist, c_obs]``.
        collision_free: every executed plan was collision-free.
    """

    requested: Behavior
    behavior: Behavior
    v_ref: float
    duration: float
    n_steps: int
    reason: str
    c_total: float
    c_terms: tuple[float, float, float]
    collision_free: bool


class BehaviorExecutor:
    """Runs one behavior at a time (see the module docstring for the protocol)."""

    def __init__(
        self,
        planner: PlannerConfig = PlannerConfig(),
        config: ExecutorConfig = ExecutorConfig(),
        behavior_cfg: BehaviorConfig = BehaviorConfig(),
        vehicle: VehicleParams = VehicleParams(),
        tracker: TrackerConfig = TrackerConfig(),
    ):
        self.planner_cfg, self.cfg, self.behavior_cfg = planner, config, behavior_cfg
        self.tracker = TrajectoryTracker(vehicle, tracker)
        self._started = False
        self._done = True
        self._reason = "idle"

    # ------------------------------------------------------------------ protocol
    def start(self, behavior: Behavior | int, ego: VehicleState, refs: ReferencePaths | tuple,
              speed_limit: float) -> Behavior:
        """Begin ``behavior`` from ``ego``; returns the effective behavior."""
        refs = ReferencePaths(*refs)
        if refs.current is None:
            raise ValueError("refs.current (the current lane centerline) is required")
        for p in refs.paths:
            if p is not None and not isinstance(p, Path):
                raise ValueError(f"reference paths must be Path or None, got {type(p).__name__}")
        if not (math.isfinite(speed_limit) and speed_limit > 0):
            raise ValueError(f"speed_limit must be finite and > 0 [m/s], got {speed_limit!r}")
        self.requested = Behavior(int(behavior))
        self.behavior, self.target = target_path(self.requested, refs)
        self.speed_limit = float(speed_limit)
        changes_lane = self.behavior in (Behavior.CHANGE_LEFT, Behavior.CHANGE_RIGHT)
        self.corridor = NO_CORRIDOR if changes_lane else refs.corridor
        self.max_duration = self.cfg.max_duration if changes_lane else self.cfg.lane_keeping_max_duration
        self.v_ref = reference_speed(self.behavior, ego.v, speed_limit, self.behavior_cfg)
        self._s, *_ = self.target.project_pose(ego.x, ego.y, ego.yaw)
        self._plan: PlanResult | None = None
        self._t_since_plan = 0.0
        self.n_steps = 0
        self._costs: list[np.ndarray] = []
        self._totals: list[float] = []
        self._collision_free = True
        self._done = False
        self._reason = "running"
        self._started = True
        self.tracker.reset()
        self.last_errors = (math.nan, math.nan)
        return self.behavior

    def _finished(self, ego: VehicleState) -> str | None:
        s, e, th, _ = self.target.project_pose(ego.x, ego.y, ego.yaw, self._s)
        self._s = s
        self.last_errors = (e, th)
        c = self.cfg
        eps = 1e-9
        if self.behavior in (Behavior.CHANGE_LEFT, Behavior.CHANGE_RIGHT):
            conv = abs(e) < c.e_thresh and abs(th) < c.theta_thresh
        elif self.behavior in (Behavior.SPEED_UP, Behavior.SPEED_DOWN):
            # the planner may cap v_ref for a curve ahead: converge to the speed it can hold
            v_target = self.v_ref if self._plan is None else min(self.v_ref, self._plan.v_ref)
            conv = abs(ego.v - v_target) < c.v_thresh
        else:
            conv = True
        if conv and self.elapsed >= c.min_duration - eps:
            return "converged"
        if self.elapsed >= self.max_duration - eps:
            return "timeout"
        return None

    def step(self, ego: VehicleState,
             obstacles: Obstacles | None = None) -> tuple[Control, PlanResult]:
        """One control period: finish check, (re)plan, track.

        Returns the control to apply for the next ``dt`` and the plan it follows. After
        :attr:`done` turns True the returned control still tracks the target lane (not
        counted in the behavior's cost).
        """
        if not self._started:
            raise RuntimeError("BehaviorExecutor.step() before start()")
        obstacles = Obstacles.empty() if obstacles is None else obstacles
        ego = self._course(ego)
        if not self._done:
            reason = self._finished(ego)
            if reason is not None:
                self._done, self._reason = True, reason
        replan = self._plan is None or (self.n_steps % self.cfg.replan_every == 0) or self._done
        if replan:
            self._plan = plan(PlanningProblem(ego, self.target, self.v_ref, self.speed_limit,
                                              obstacles, s_hint=self._s, corridor=self.corridor), self.planner_cfg)
            self._t_since_plan = 0.0
        control = self.tracker.control(ego, self._plan.trajectory, self._plan.times,
                                       self.cfg.dt, self._t_since_plan)
        self._t_since_plan += self.cfg.dt
        if not self._done:
            if replan:
                self._totals.append(self._plan.c_total)
                self._costs.append(self._plan.chosen_costs)
                self._collision_free &= self._plan.collision_free
            self.n_steps += 1
        return control, self._plan

    def _course(self, ego: VehicleState) -> VehicleState:
        """``ego`` with its yaw replaced by the centre's direction of travel ``yaw + beta``.

        The planner rolls out a unicycle whose heading is the direction of travel; on the
        bicycle model the footprint centre moves at the slip angle ``beta = atan(l_r / L
        tan(steer))`` from the body yaw (~0.1 rad in a town corner). Planning, tracking and the
        finish check all use the direction of travel.
        """
        vp = self.tracker.vehicle
        if ego.steer == 0.0:
            return ego
        beta = math.atan(vp.rear_to_cg / vp.wheelbase * math.tan(ego.steer))
        return VehicleState(ego.x, ego.y, ego.yaw + beta, ego.v, ego.steer)

    # ------------------------------------------------------------------ results
    @property
    def done(self) -> bool:
        """The behavior has finished (converged or timed out) -- or none was started."""
        return self._done

    @property
    def reason(self) -> str:
        return self._reason

    @property
    def elapsed(self) -> float:
        """Executed time [s]."""
        return self.n_steps * self.cfg.dt

    @property
    def c_total(self) -> float:
        """``c~_total``: mean chosen ``c_total`` over the executed replans (0 if none)."""
        return float(np.mean(self._totals)) if self._totals else 0.0

    def reward(self, scale: float | None = None) -> float:
        """``r_k = -scale * c~_total`` (``scale`` defaults to ``ExecutorConfig.reward_scale``)."""
        return reward_from_cost(self.c_total, self.cfg.reward_scale if scale is None else scale)

    def outcome(self) -> BehaviorOutcome:
        if not self._started:
            raise RuntimeError("BehaviorExecutor.outcome() before start()")
        terms = np.mean(self._costs, axis=0) if self._costs else np.zeros(3)
        return BehaviorOutcome(
            requested=self.requested, behavior=self.behavior, v_ref=self.v_ref,
            duration=self.elapsed, n_steps=self.n_steps, reason=self._reason,
            c_total=self.c_total, c_terms=tuple(float(t) for t in terms),
            collision_free=self._collision_free)
