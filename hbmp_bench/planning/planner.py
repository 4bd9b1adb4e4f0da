"""Behavior-conditioned sampling motion planner (paper: "Behavior Conditioned Motion Planner").

Given a reference path (the target lane's centerline) and a reference speed ``v_ref``,
:func:`plan` spans DWA-like samples of the initial speed ``v(0)`` and angular velocity
``omega(0)``, rolls every sample forward with the lane-converging control law of
:mod:`.control` (so all samples converge to the reference lane, unlike plain DWA), scores
them and returns the cheapest collision-free one.

Samples (S = n_v * n_omega + 2):

* ``v(0) = v + linspace(-decel, +accel, n_v) * v_window_time`` (the dynamic window of one
  control period by default), clipped to ``[0, max(v, speed_limit)]``; ``v(t)`` then follows
  :func:`.control.linear_speed_profile` from ``v(0)`` to ``v_ref``.
* ``omega(0) = omega_nom + d_omega``, ``d_omega in linspace(-omega_spread, +omega_spread,
  n_omega)``, where ``omega_nom`` is the control law at the current state; the offset
  ``d_omega`` is added to the control law for ``omega_hold`` [s], then the plain control law
  takes over (so the ``d_omega = 0`` sample is the pure control-law trajectory).
* two braking samples that follow the lane with the control law: a comfortable stop
  (``decel``) and a full brake (``brake_decel``), index ``brake_index`` (always present).

Roll-out (kinematic unicycle, ``k = 0 .. n_steps - 1``)::

    x += v_k cos(psi + omega_k dt / 2) dt;  y += v_k sin(psi + omega_k dt / 2) dt;
    psi += omega_k dt

with ``omega_k`` = control law at step k (gains scheduled above ``gain_speed``) clipped to
:func:`.control.omega_limit` (yaw-rate limit, curvature / steering limit
``max_curvature |v|``, lateral-acceleration limit). The midpoint heading is the exact chord
direction of a constant-``omega`` arc; plain Euler with ``cos(psi)`` drifts systematically
to the outside of curves (~0.1 m at 8 m/s on R = 40 m). ``(s, e, theta_e, kappa)`` of
every sample is re-projected on the reference at every step (windowed search on a local
uniformly resampled copy, ``path_resolution`` m).

Costs per sample, over the future steps ``t_k = k dt, k = 1..n_steps``:

* ``c_velocity = sum_k t_k^2 |v_ref - v(t_k)| / sum_k t_k^2``  [m/s] (paper, exactly);
* ``c_dist = 1 / (1 + sum_k |v(t_k)|)`` (paper's form, exactly: the sum is over the
  planning steps of speeds in m/s, i.e. travelled distance / dt; units 1/(m/s));
* ``c_obs`` -- the paper writes ``sum_t d_olon(t) + kappa d_olat(t)``, which would *reward*
  being close to obstacles; we keep its combined distance ``d = d_lon + kappa_obs d_lat``
  but turn it into a proximity penalty::

      c_obs = mean_k sum_o exp(-(g_lon + kappa_obs g_lat) / sigma_obs)

  where ``g_lon = max(|s_o - s| - (L + L_o)/2, 0)`` and ``g_lat = max(|e_o - e| - (W + W_o)/2,
  0)`` are the bumper-to-bumper longitudinal and side-to-side lateral gaps [m] between the
  sample and obstacle ``o`` in the reference path's curvilinear frame. Obstacles are
  projected once at t = 0 and predicted at constant ``(s_dot, e_dot)`` in that frame (this
  keeps lane-following cars in their lane on curves; on straight paths it equals the
  Cartesian constant-velocity prediction). Dimensionless, in ``[0, K]``.
* ``c_total = w_velocity c_velocity + w_dist c_dist + w_obs c_obs``.

Collision check: ego footprint (``length`` x ``width`` inflated by ``safety_margin`` on
each side) against obstacle footprints (oriented rectangles, Cartesian constant-velocity
prediction along their heading) at every future step: bounding-circle broad phases
(per-step sample bounding box, then per sample) followed by an exact separating-axis test
on the candidate pairs. A sample that touches an obstacle is infeasible. A follower (wholly behind the ego,
in its line, heading its way) is left out of this check and kept in ``c_obs``
(``PlannerConfig.ignore_followers``): braking in front of it is lawful, keeping its distance its own part.

Compiled: :func:`plan` runs the samples, roll-outs, ``c_obs`` and collision check in one numba
kernel (:func:`.plan_kernel.plan_samples`, which calls :mod:`.rollout` and :mod:`.obstacle_kernels`);
``c_velocity``, ``c_dist`` and the choice stay numpy. :func:`plan_reference` is the same call in numpy
around the roll-out and obstacle kernels; the tests hold the two to equal arrays, bit for bit. The
obstacle kernels' own numpy form is :func:`obstacle_cost_reference` and :func:`first_contacts_reference`:
the same first contacts, ``c_obs`` within 5e-6 relative (the reference sums in float32), the same chosen
trajectory on recorded problems. The cheapest
feasible sample is chosen (ties within ``tie_tolerance`` go to the sample nearest the
nominal one), among those that stay on the road where any does (the problem's ``corridor``, an
addition to the paper: its costs have no road edge, and with a car alongside, re-planning at 10 Hz
chose the sample that swerved away first again and again, a ratchet that drifted the ego off a
highway's outer lane, 1.1 m off its centre at 20 m/s; a sample may stray as far as the control law
does at its speed, see :func:`on_road`). If none is feasible, ``collision_free`` is False and
the chosen sample is the one whose first predicted contact comes latest; among ties the slowest at that
contact where what it meets lies ahead of the ego's centre, else the cheapest (:func:`met_ahead`;
``infeasible_fallback="latest_contact"``, default: the full brake before a pedestrian stopped ahead,
moving on before a car closing from behind), the full brake (``"brake"``) or the cheapest one
(``"min_cost"``). ``min_cost`` kept 3-5 m/s into pedestrians stopped on a crossing; ``brake`` stopped a slow
lane change in front of the car it was leaving behind, which ran into it
(``docs/experiments/planner-brake-fallback/``). The full brake index is always reported in
:attr:`PlanResult.brake_index`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from .control import control_law, linear_speed_profile, omega_limit
from .frame import Path
from .state import Obstacles, VehicleState

from hbmp_bench.errors import ConfigError

__all__ = ["PlannerConfig", "PlanningProblem", "PlanResult", "plan", "plan_reference", "compile_kernels",
           "COST_NAMES"]

#: Column names of :attr:`PlanResult.costs`.
COST_NAMES = ("velocity", "dist", "obs")


def _pos(name, value, allow_zero=False, allow_inf=False):
    ok = value >= 0 if allow_zero else value > 0
    if not ok or value != value or (not allow_inf and math.isinf(value)):
        rel = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"PlannerConfig.{name} must be finite and {rel}, got {value!r}")


INFEASIBLE_FALLBACKS = ("latest_contact", "brake", "min_cost")
"""The choices of :attr:`PlannerConfig.infeasible_fallback`."""


@dataclass(frozen=True)
class PlannerConfig:
    """Planner parameters (SI units).

    Attributes:
        horizon: planning horizon [s] (an integer multiple of ``dt``).
        dt: roll-out step [s] (the control / replanning period).
        n_v: number of ``v(0)`` samples.
        n_omega: number of ``omega(0)`` samples.
        v_window_time: ``v(0)`` spans ``[-decel, +accel] * v_window_time`` around the
            current speed [s] (DWA window; default one control period).
        omega_spread: ``omega(0)`` spans ``omega_nom +- omega_spread`` [rad/s].
        omega_hold: the ``omega(0)`` offset is applied this long before the plain control
            law takes over [s] (at least one step).
        accel: acceleration of the speed profile [m/s^2].
        decel: deceleration of the speed profile and of the comfortable stop [m/s^2].
        brake_decel: deceleration of the full-brake sample [m/s^2].
        yaw_rate_max: yaw-rate limit [rad/s].
        max_curvature: path curvature limit from steering, ``|omega| <= max_curvature |v|``
            [1/m] (0.2 ~ tan(0.5 rad) / 2.8 m wheelbase).
        lat_accel_max: lateral-acceleration limit ``|omega v|`` [m/s^2] (``inf`` disables).
        k_theta: heading gain of the control law [1/m].
        k_e: lateral gain of the control law [1/m^2] (``k_theta = 2 sqrt(k_e)`` is
            critically damped in distance).
        gain_speed: above this speed [m/s] the gains are scheduled as
            ``k_theta * (gain_speed / |v|)`` and ``k_e * (gain_speed / |v|)^2`` (same damping
            ratio, time-domain bandwidth capped) so lane changes at highway speed do not
            saturate the lateral-acceleration limit and overshoot; ``inf`` = constant gains
            exactly as in the paper.
        w_velocity, w_dist, w_obs: weights of the cost terms.
        kappa_obs: lateral weight ``kappa`` in ``d_lon + kappa d_lat`` of ``c_obs``.
        sigma_obs: length scale of the ``c_obs`` exponential [m].
        length, width: ego footprint [m].
        safety_margin: footprint inflation on each side for the collision check [m].
        path_resolution: spacing of the local resampled reference used in roll-outs [m].
        tie_tolerance: samples whose ``c_total`` is within this of the minimum count as
            tied; among them the one closest to the nominal sample (smallest normalised
            ``|omega(0) - omega_nom|`` + ``|v(0) - v|``) is chosen. Without it, exact ties
            (e.g. no obstacles: the paper's costs do not depend on ``omega``) would pick an
            arbitrary swerving sample.
        infeasible_fallback: the choice when nothing is collision-free: ``"latest_contact"`` (the sample
            whose first predicted contact comes latest; ties to the slowest at that contact when it is met
            ahead of the ego's centre, else to the cheapest), ``"brake"``
            (the full brake) or ``"min_cost"`` (the cheapest sample).
        curve_lat_accel: lateral acceleration the speed profile allows in curves [m/s^2]
            (``inf`` disables the curve speed cap, see :func:`curve_speed_cap`).
        ignore_followers: leave out of the collision check the obstacles that follow the ego (wholly
            behind it along the path, in its line, heading its way: :func:`.obstacle_kernels.followers`);
            they stay in ``c_obs``. Keeping its distance is the follower's part: predicted at constant
            speed, a close follower made every slowing sample infeasible, and the fallback then took the
            cheapest, fast one into the queue ahead (not in the paper; ``nocrash-dense``: most of
            ``hbmp``'s 49 collision episodes of 125 rear-ended a stopped car with a car close behind).
    """

    horizon: float = 3.0
    dt: float = 0.1
    n_v: int = 7
    n_omega: int = 9
    v_window_time: float = 0.1
    omega_spread: float = 0.3
    omega_hold: float = 0.5
    accel: float = 2.0
    decel: float = 3.0
    brake_decel: float = 6.0
    yaw_rate_max: float = 0.6
    max_curvature: float = 0.2
    lat_accel_max: float = 4.0
    k_theta: float = 0.7
    k_e: float = 0.12
    gain_speed: float = 6.0
    w_velocity: float = 1.0
    w_dist: float = 1.0
    w_obs: float = 1.0
    kappa_obs: float = 20.0
    sigma_obs: float = 10.0
    length: float = 4.6
    width: float = 1.9
    safety_margin: float = 0.2
    path_resolution: float = 1.0
    tie_tolerance: float = 1e-3
    infeasible_fallback: str = "latest_contact"
    curve_lat_accel: float = 2.0
    ignore_followers: bool = True

    def __post_init__(self):
        for name in ("horizon", "dt", "accel", "decel", "brake_decel", "yaw_rate_max",
                     "max_curvature", "k_theta", "k_e", "sigma_obs", "length", "width",
                     "path_resolution"):
            _pos(name, getattr(self, name))
        for name in ("v_window_time", "omega_spread", "omega_hold", "w_velocity", "w_dist",
                     "w_obs", "kappa_obs", "safety_margin", "tie_tolerance"):
            _pos(name, getattr(self, name), allow_zero=True)
        _pos("lat_accel_max", self.lat_accel_max, allow_inf=True)
        _pos("gain_speed", self.gain_speed, allow_inf=True)
        _pos("curve_lat_accel", self.curve_lat_accel, allow_inf=True)
        for name in ("n_v", "n_omega"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < 1:
                raise ConfigError(f"PlannerConfig.{name} must be an int >= 1, got {v!r}")
        n = round(self.horizon / self.dt)
        if n < 1 or abs(n * self.dt - self.horizon) > 1e-6 * max(1.0, self.horizon):
            raise ConfigError(
                f"PlannerConfig.horizon ({self.horizon}) must be a positive multiple of "
                f"dt ({self.dt})")
        if self.infeasible_fallback not in INFEASIBLE_FALLBACKS:
            raise ConfigError(
                f"PlannerConfig.infeasible_fallback must be one of {', '.join(INFEASIBLE_FALLBACKS)}, "
                f"got {self.infeasible_fallback!r}")

    @property
    def n_steps(self) -> int:
        """Number of roll-out steps (trajectories have ``n_steps + 1`` points)."""
        return round(self.horizon / self.dt)

    @property
    def n_samples(self) -> int:
        """S = ``n_v * n_omega + 2`` (grid + comfortable stop + full brake)."""
        return self.n_v * self.n_omega + 2


NO_CORRIDOR = (-math.inf, math.inf, math.inf)
"""A :class:`PlanningProblem` corridor without bounds."""


@dataclass(frozen=True, eq=False)
class PlanningProblem:
    """One planning query.

    Attributes:
        ego: current ego state (footprint centre, yaw, speed).
        path: reference path = centerline of the target lane.
        v_ref: reference speed [m/s] (>= 0).
        speed_limit: lane speed limit [m/s] (> 0); caps the ``v(0)`` samples.
        obstacles: surrounding vehicles (predicted at constant velocity); an
            :class:`Obstacles`, a ``(K, 6)`` array of ``x, y, yaw, v, length, width`` rows, or
            ``None``. Must not contain the ego itself.
        s_hint: optional previous arc length of the ego on ``path`` [m] (windowed search).
        corridor: the road beside the path, ``(e_right, e_left, s_end)``: the lateral offsets [m]
            (right negative) the footprint centre may take up to arc length ``s_end`` [m] of
            ``path`` (the end of the ego's lane) without leaving the road. Samples that stray further
            (than the ego already is, and than the control law at their speed does: :func:`on_road`) are
            chosen only when no collision-free sample stays inside (:attr:`PlanResult.on_road`). Default: no
            bounds.
    """

    ego: VehicleState
    path: Path
    v_ref: float
    speed_limit: float
    obstacles: Obstacles = field(default_factory=Obstacles.empty)
    s_hint: float | None = None
    corridor: tuple[float, float, float] = NO_CORRIDOR

    def __post_init__(self):
        if not isinstance(self.ego, VehicleState):
            raise ConfigError(f"ego must be a VehicleState, got {type(self.ego).__name__}")
        if not isinstance(self.path, Path):
            raise ConfigError(f"path must be a Path, got {type(self.path).__name__}")
        if self.obstacles is None:
            object.__setattr__(self, "obstacles", Obstacles.empty())
        elif not isinstance(self.obstacles, Obstacles):
            arr = np.asarray(self.obstacles, dtype=float)
            if arr.ndim != 2 or arr.shape[1] != 6:
                raise ConfigError("obstacles must be Obstacles or a (K, 6) array of "
                                 f"x, y, yaw, v, length, width; got shape {arr.shape}")
            object.__setattr__(self, "obstacles", Obstacles.from_rows(arr))
        if not (np.isfinite(self.v_ref) and self.v_ref >= 0):
            raise ConfigError(f"v_ref must be finite and >= 0 [m/s], got {self.v_ref!r}")
        if not (np.isfinite(self.speed_limit) and self.speed_limit > 0):
            raise ConfigError(f"speed_limit must be finite and > 0 [m/s], got {self.speed_limit!r}")
        if self.s_hint is not None and not np.isfinite(self.s_hint):
            raise ConfigError(f"s_hint must be finite or None, got {self.s_hint!r}")
        if len(self.corridor) != 3 or any(np.isnan(self.corridor)) or not self.corridor[0] < self.corridor[1]:
            raise ConfigError(f"corridor must be (e_right, e_left, s_end) [m] with e_right < e_left, got {self.corridor!r}")


@dataclass(frozen=True, eq=False)
class PlanResult:
    """All samples of one planning call and the choice.

    Attributes:
        times: (T,) times [s], ``T = n_steps + 1``, ``times[0] = 0`` (current pose).
        trajectories: (S, T, 4) ``[x, y, yaw, v]`` [m, m, rad, m/s]; yaw is continuous (not
            wrapped); row 0 is the current pose with the sampled ``v(0)``.
        omega: (S, T - 1) angular velocity applied during each step [rad/s].
        frenet: (S, T, 2) ``[s, e]`` of each point on the reference path [m].
        costs: (S, 3) ``[c_velocity, c_dist, c_obs]`` (see :data:`COST_NAMES`).
        total: (S,) ``c_total``.
        feasible: (S,) collision-free mask.
        contact_time: (S,) time of each sample's first predicted contact with a checked obstacle [s];
            ``inf`` where it has none (the feasible samples).
        on_road: (S,) mask of the samples that stay within the problem's ``corridor``.
        chosen: index of the chosen sample: the cheapest collision-free one on the road, else the
            cheapest collision-free one, else the ``infeasible_fallback``'s (see the module docstring).
        collision_free: whether the chosen sample is collision-free.
        brake_index: index of the full-brake sample.
        v_ref: reference speed used [m/s]: the problem's, capped for curves ahead
            (:func:`curve_speed_cap`).
    """

    times: np.ndarray
    trajectories: np.ndarray
    omega: np.ndarray
    frenet: np.ndarray
    costs: np.ndarray
    total: np.ndarray
    feasible: np.ndarray
    contact_time: np.ndarray
    on_road: np.ndarray
    chosen: int
    collision_free: bool
    brake_index: int
    v_ref: float

    @property
    def trajectory(self) -> np.ndarray:
        """(T, 4) chosen trajectory ``[x, y, yaw, v]``."""
        return self.trajectories[self.chosen]

    @property
    def c_total(self) -> float:
        """``c_total`` of the chosen sample."""
        return float(self.total[self.chosen])

    @property
    def chosen_costs(self) -> np.ndarray:
        """(3,) cost terms of the chosen sample."""
        return self.costs[self.chosen]

    @property
    def n_samples(self) -> int:
        return len(self.total)


# ---------------------------------------------------------------------------- helpers
def _spread(lo: float, hi: float, n: int) -> np.ndarray:
    """``n`` offsets spanning ``[lo, hi]``; a single sample is the nominal one (offset 0)."""
    return np.zeros(1) if n == 1 else np.linspace(lo, hi, n)


class _Layout(NamedTuple):
    """What every :func:`plan` call with one config shares (read-only arrays, built once per config)."""

    times: np.ndarray  # (T,) [s]
    dv: np.ndarray  # (n_v,) offsets of v(0) from the speed [m/s]
    dw: np.ndarray  # (n_omega,) offsets of omega(0) from omega_nom [rad/s]
    dec: np.ndarray  # (S,) deceleration of each sample's speed profile [m/s^2]
    t2: np.ndarray  # (T - 1,) squared future times [s^2]
    t2_sum: float  # sum of t2 [s^2]
    params: np.ndarray  # (24,) the scalars :func:`.plan_kernel.plan_samples` reads (:func:`kernel_params`)
    hold: int  # steps the omega(0) offset is held
    lane_following: np.ndarray  # (S,) each sample's lane-following sample: its speed row's omega offset 0


def _lane_following(n_v: int, dw: np.ndarray) -> np.ndarray:
    """(S,) for each sample the index of the sample with its ``v(0)`` whose ``omega(0)`` offset (``dw``,
    (n_omega,)) is the smallest (0 for an odd ``n_omega``): the plain lane-converging control law at that
    speed. The two braking samples follow the control law themselves."""
    n_omega = len(dw)
    n_grid = n_v * n_omega
    rows = np.repeat(np.arange(n_v), n_omega) * n_omega + int(np.argmin(np.abs(dw)))
    return np.concatenate([rows, [n_grid, n_grid + 1]])


@functools.lru_cache(maxsize=16)
def _layout(cfg: PlannerConfig) -> _Layout:
    n_grid = cfg.n_v * cfg.n_omega
    times = np.arange(cfg.n_steps + 1) * cfg.dt
    dw = _spread(-cfg.omega_spread, cfg.omega_spread, cfg.n_omega)
    layout = _Layout(
        times=times,
        dv=_spread(-cfg.decel * cfg.v_window_time, cfg.accel * cfg.v_window_time, cfg.n_v),
        dw=dw,
        dec=np.concatenate([np.full(n_grid, cfg.decel), [cfg.decel, cfg.brake_decel]]),
        t2=times[1:] ** 2,
        t2_sum=float((times[1:] ** 2).sum()),
        params=kernel_params(cfg),
        hold=max(1, round(cfg.omega_hold / cfg.dt)),
        lane_following=_lane_following(cfg.n_v, dw),
    )
    for a in layout:
        if isinstance(a, np.ndarray):
            a.setflags(write=False)
    return layout


def kernel_params(cfg: PlannerConfig) -> np.ndarray:
    """(24,) the config's scalars in the order :func:`.plan_kernel.plan_samples` unpacks them: ``dt, n_v,
    n_omega, hold, horizon, accel, decel, yaw_rate_max, max_curvature, lat_accel_max, k_theta, k_e,
    gain_speed, kappa_obs, sigma_obs, length, width, safety_margin, path_resolution, curve_lat_accel``, the
    two tie-breaking scales of ``dev`` [rad/s, m/s], :data:`OBS_EXPONENT_CUTOFF` and ``ignore_followers`` (1/0)."""
    return np.array([
        cfg.dt, cfg.n_v, cfg.n_omega, max(1, round(cfg.omega_hold / cfg.dt)), cfg.horizon, cfg.accel, cfg.decel,
        cfg.yaw_rate_max, cfg.max_curvature, cfg.lat_accel_max, cfg.k_theta, cfg.k_e, cfg.gain_speed,
        cfg.kappa_obs, cfg.sigma_obs, cfg.length, cfg.width, cfg.safety_margin, cfg.path_resolution,
        cfg.curve_lat_accel, max(cfg.omega_spread, 1e-9), max((cfg.accel + cfg.decel) * cfg.v_window_time, 1e-9),
        OBS_EXPONENT_CUTOFF, float(cfg.ignore_followers)], dtype=np.float64)


def _sat_overlap(dx, dy, ce, se, hl_e, hw_e, co, so, hl_o, hw_o):
    """Separating-axis test of oriented rectangles (all arrays (P,)); True = overlap.

    ``(dx, dy)`` is the centre offset obstacle - ego; ``(ce, se)`` / ``(co, so)`` the cosine
    and sine of the two headings; ``hl``/``hw`` half length / width [m].
    """
    cd = np.abs(ce * co + se * so)  # |cos(psi_e - psi_o)|
    sd = np.abs(se * co - ce * so)  # |sin(psi_e - psi_o)|
    sep = np.abs(dx * ce + dy * se) > hl_e + hl_o * cd + hw_o * sd
    sep |= np.abs(-dx * se + dy * ce) > hw_e + hl_o * sd + hw_o * cd
    sep |= np.abs(dx * co + dy * so) > hl_o + hl_e * cd + hw_e * sd
    sep |= np.abs(-dx * so + dy * co) > hw_o + hl_e * sd + hw_e * cd
    return ~sep


def first_contacts_reference(X, Y, PSI, obs: Obstacles, times, cfg: PlannerConfig) -> np.ndarray:
    """(S,) int: the first step (index into ``times``) at which a sample's footprint meets an obstacle;
    ``T = len(times)`` where it meets none.

    The numpy reference of the compiled :func:`.obstacle_kernels.first_contacts` that :func:`plan`
    uses (the tests hold the two to the same steps).

    ``X, Y, PSI``: (T, S) ego poses (time-major) at ``times`` (T,). Broad phase 1:
    obstacle bounding circles against the per-step bounding box of all samples, (K, T);
    broad phase 2: bounding circles against each sample on the surviving (obstacle, step)
    pairs; narrow phase: exact separating-axis test.
    """
    T, S = X.shape
    first = np.full(S, T, dtype=np.int64)
    if len(obs) == 0:
        return first
    hl_e = 0.5 * cfg.length + cfg.safety_margin
    hw_e = 0.5 * cfg.width + cfg.safety_margin
    r_e = math.hypot(hl_e, hw_e)
    ox, oy = obs.predict(times)  # (K, T)
    reach = (r_e + 0.5 * np.hypot(obs.length, obs.width))[:, None]
    near = ((ox + reach >= X.min(axis=1)) & (ox - reach <= X.max(axis=1))
            & (oy + reach >= Y.min(axis=1)) & (oy - reach <= Y.max(axis=1)))
    ki, ti = np.nonzero(near)
    if len(ki) == 0:
        return first
    dx = ox[ki, ti][:, None] - np.take(X, ti, axis=0)  # (P, S)
    dy = oy[ki, ti][:, None] - np.take(Y, ti, axis=0)
    rr = reach[ki]
    pi, si = np.nonzero(dx * dx + dy * dy <= rr * rr)
    if len(si) == 0:
        return first
    ki, ti = ki[pi], ti[pi]
    psi = PSI[ti, si]
    yaw_o = obs.yaw[ki]
    over = _sat_overlap(dx[pi, si], dy[pi, si], np.cos(psi), np.sin(psi), hl_e, hw_e,
                        np.cos(yaw_o), np.sin(yaw_o), 0.5 * obs.length[ki], 0.5 * obs.width[ki])
    np.minimum.at(first, si[over], ti[over])
    return first


#: Obstacle-step pairs whose ``c_obs`` exponent exceeds this for every sample are skipped
#: (each would add less than ``exp(-10) = 4.5e-5``).
OBS_EXPONENT_CUTOFF = 10.0


def obstacle_cost_reference(SS, EE, obs: Obstacles, lp: Path, times, cfg: PlannerConfig) -> np.ndarray:
    """(S,) ``c_obs`` from sample Frenet coordinates ``SS, EE`` (T, S) at ``times`` (T,).

    The numpy reference of :func:`_obstacle_cost` (which runs the compiled
    :func:`.obstacle_kernels.obstacle_cost`); it sums in float32, the kernel in float64.
    """
    T, S = SS.shape
    if len(obs) == 0:
        return np.zeros(S)
    so0, eo0, tho, _ = lp.project(np.stack([obs.x, obs.y], axis=1), obs.yaw)
    so = so0[:, None] + (obs.v * np.cos(tho))[:, None] * times  # (K, T)
    eo = eo0[:, None] + (obs.v * np.sin(tho))[:, None] * times
    half_l = (0.5 * (cfg.length + obs.length))[:, None]
    half_w = (0.5 * (cfg.width + obs.width))[:, None]
    # lower bound of the exponent over all samples, per (obstacle, step)
    glon = np.maximum(np.maximum(so - SS.max(axis=1), SS.min(axis=1) - so) - half_l, 0.0)
    glat = np.maximum(np.maximum(eo - EE.max(axis=1), EE.min(axis=1) - eo) - half_w, 0.0)
    ki, ti = np.nonzero(glon + cfg.kappa_obs * glat < OBS_EXPONENT_CUTOFF * cfg.sigma_obs)
    if len(ki) == 0:
        return np.zeros(S)
    # (P, S) gaps in float32 (plenty for a penalty, ~2x faster)
    g = np.abs(np.take(SS, ti, axis=0).astype(np.float32) - so[ki, ti, None].astype(np.float32))
    g -= half_l[ki].astype(np.float32)
    np.maximum(g, 0.0, out=g)
    gl = np.abs(np.take(EE, ti, axis=0).astype(np.float32) - eo[ki, ti, None].astype(np.float32))
    gl -= half_w[ki].astype(np.float32)
    np.maximum(gl, 0.0, out=gl)
    gl *= np.float32(cfg.kappa_obs)
    g += gl
    g *= np.float32(-1.0 / cfg.sigma_obs)
    np.exp(g, out=g)
    return g.sum(axis=0, dtype=np.float64) / T


def _obstacle_cost(SS, EE, obs: Obstacles, lp: Path, times, cfg: PlannerConfig) -> np.ndarray:
    """(S,) ``c_obs`` of samples at Frenet coordinates ``SS, EE`` (T, S) at ``times`` (T,) on the
    uniformly resampled reference ``lp`` (compiled: :func:`.obstacle_kernels.obstacle_cost`;
    numpy reference: :func:`obstacle_cost_reference`)."""
    from .obstacle_kernels import obstacle_cost, project_poses

    if len(obs) == 0:
        return np.zeros(SS.shape[1])
    # Obstacles holds C-contiguous float64 arrays: with these the kernels keep one compiled signature
    seg = lp.uniform_segments()
    so0, eo0, tho = project_poses(obs.x, obs.y, obs.yaw, seg.x0, seg.y0, seg.tx, seg.ty, seg.chord, seg.s,
                                  seg.heading, seg.dh)
    return obstacle_cost(np.ascontiguousarray(SS), np.ascontiguousarray(EE), so0, eo0, tho, obs.v, obs.length,
                         obs.width, np.ascontiguousarray(times, dtype=np.float64), float(cfg.length),
                         float(cfg.width), float(cfg.kappa_obs), float(cfg.sigma_obs), OBS_EXPONENT_CUTOFF)


def collision_checked(obs: Obstacles, lp: Path, s0: float, e0: float, cfg: PlannerConfig) -> Obstacles:
    """The obstacles the collision check tests: all, or with ``cfg.ignore_followers`` all but the ego's
    followers (:func:`.obstacle_kernels.followers`; the ego at ``s0, e0`` [m] on the local reference ``lp``)."""
    from .obstacle_kernels import followers, project_poses

    if not cfg.ignore_followers or len(obs) == 0:
        return obs
    seg = lp.uniform_segments()
    so0, eo0, tho = project_poses(obs.x, obs.y, obs.yaw, seg.x0, seg.y0, seg.tx, seg.ty, seg.chord, seg.s,
                                  seg.heading, seg.dh)
    return obs.subset(~followers(so0, eo0, tho, obs.length, obs.width, float(s0), float(e0), float(cfg.length),
                                 float(cfg.width)))


def _first_contacts(X, Y, PSI, obs: Obstacles, times, cfg: PlannerConfig) -> np.ndarray:
    """(S,) the first step (index into ``times`` (T,)) at which a sample's footprint (``X, Y, PSI``
    (T, S)) meets an obstacle, ``T`` where none (compiled: :func:`.obstacle_kernels.first_contacts`;
    numpy reference: :func:`first_contacts_reference`)."""
    from .obstacle_kernels import first_contacts

    if len(obs) == 0:
        return np.full(X.shape[1], X.shape[0], dtype=np.int64)
    return first_contacts(np.ascontiguousarray(X), np.ascontiguousarray(Y), np.ascontiguousarray(PSI),
                          obs.x, obs.y, obs.yaw, obs.v, obs.length, obs.width,
                          np.ascontiguousarray(times, dtype=np.float64), 0.5 * cfg.length + cfg.safety_margin,
                          0.5 * cfg.width + cfg.safety_margin)


def instant_costs(path: Path, ego: VehicleState, obstacles: Obstacles,
                  cfg: PlannerConfig | None = None) -> tuple[float, float]:
    """``(c_dist, c_obs)`` of the ego's state now, with the planner's formulas at one instant.

    ``c_dist = 1 / (1 + |v|)`` and ``c_obs = sum_o exp(-(g_lon + kappa_obs g_lat) / sigma_obs)``
    with the gaps measured in ``path``'s curvilinear frame (see the module docstring). Used to
    reward a controller that has no planner (the flat baseline): the paper's r_t without the
    velocity term, which needs a behavior's v_ref.
    """
    cfg = PlannerConfig() if cfg is None else cfg
    s, e, _, _ = path.project(ego.xy, ego.yaw)
    c_dist = 1.0 / (1.0 + abs(ego.v))
    if len(obstacles) == 0:
        return c_dist, 0.0
    lp = path.resample(cfg.path_resolution, s - 60.0, s + 60.0, extrapolate=True)
    c_obs = float(_obstacle_cost(np.array([[s]]), np.array([[e]]), obstacles, lp, np.zeros(1), cfg)[0])
    return c_dist, c_obs


# ---------------------------------------------------------------------------- planner
def curve_speed_cap(path: Path, s0: float, v: float, cfg: PlannerConfig) -> float:
    """Highest speed [m/s] now from which the ego can still slow to every curve ahead.

    A curve of curvature ``kappa`` at arc length ``s`` allows ``v_k = min(sqrt(curve_lat_accel /
    |kappa|), yaw_rate_max / |kappa|)`` (lateral-acceleration and yaw-rate limits); from ``s0``
    the ego can reach it braking at ``decel`` if ``v <= sqrt(v_k^2 + 2 decel (s - s0))``. The
    cap is the minimum over the path from ``s0 - 2`` m to a preview of the horizon at the current
    speed plus the braking distance from it (``inf`` on straight roads or with
    ``curve_lat_accel = inf``). Not in the paper, whose lanes are gentle: without it a turn at
    CARLA-town corners (R ~ 8 m) taken at the town speed limit leaves the lane.
    """
    if not np.isfinite(cfg.curve_lat_accel):
        return np.inf
    preview = max(v, 1.0) * cfg.horizon + v * v / (2.0 * cfg.decel) + 5.0
    s = np.arange(s0 - 2.0, s0 + preview, cfg.path_resolution)
    kappa = np.abs(path.point_at(s)[3])
    bent = kappa > 1e-4
    if not bent.any():
        return np.inf
    k = kappa[bent]
    v_curve = np.minimum(np.sqrt(cfg.curve_lat_accel / k), cfg.yaw_rate_max / k)
    reach = np.maximum(s[bent] - s0, 0.0)
    return float(np.min(np.sqrt(v_curve ** 2 + 2.0 * cfg.decel * reach)))


def plan(problem: PlanningProblem, cfg: PlannerConfig | None = None) -> PlanResult:
    """Sample, roll out, score and choose a trajectory (see the module docstring).

    Compiled: :func:`.plan_kernel.plan_samples` builds the samples, rolls them out and runs the obstacle
    stage in one call; ``c_velocity``, ``c_dist`` and the choice are the numpy of :func:`plan_reference`,
    whose results this gives bit for bit.
    """
    from .plan_kernel import plan_samples  # numba loads on the first call

    cfg = PlannerConfig() if cfg is None else cfg
    layout = _layout(cfg)
    ego, path, obs = problem.ego, problem.path, problem.obstacles
    ps, x0, y0, tx, ty, chord, heading, kappa, dh, dk = path.segment_arrays()
    traj, omega, frenet, V, c_obs, first, dev, v_ref = plan_samples(
        float(ego.x), float(ego.y), float(ego.yaw), float(ego.v),
        np.nan if problem.s_hint is None else float(problem.s_hint), float(problem.v_ref), float(problem.speed_limit),
        ps, x0, y0, tx, ty, chord, heading, kappa, dh, dk,
        obs.x, obs.y, obs.yaw, obs.v, obs.length, obs.width,
        layout.times, layout.dv, layout.dw, layout.dec, layout.params)
    Vf = V[:, 1:]
    c_vel = (np.abs(v_ref - Vf) @ layout.t2) / layout.t2_sum
    c_dist = 1.0 / (1.0 + np.abs(Vf).sum(axis=1))
    return _choose(cfg, layout.times, traj, omega, frenet, c_vel, c_dist, c_obs, first, dev, v_ref,
                   on_road(frenet, problem.corridor, layout.lane_following), obs)


def on_road(frenet: np.ndarray, corridor: tuple[float, float, float],
            lane_following: np.ndarray | None = None) -> np.ndarray:
    """(S,) which samples keep their centre within ``corridor`` = ``(e_right, e_left, s_end)`` (see
    :class:`PlanningProblem`) at every future point with ``s <= s_end``, or no further out than the ego
    is now, or than ``lane_following`` (S,) allows: each sample may stray as far out as the sample of
    that index does (:func:`_lane_following`: the control law at its speed, whose own swing is no
    choice of the planner's; a car standing 0.86 m left of a 0.85 m corridor, heading out, swings 0.15 m
    further before the law turns it, and without the allowance only the stop samples stayed on the
    road: it stood 41 s asking to go). ``frenet``: (S, T, 2) ``[s, e]`` [m], point 0 the current pose."""
    e_right, e_left, s_end = corridor
    if e_right == -np.inf and e_left == np.inf:
        return np.ones(len(frenet), dtype=bool)
    e_now = float(frenet[0, 0, 1])
    s, e = frenet[:, 1:, 0], frenet[:, 1:, 1]
    out = np.maximum(e - max(e_left, e_now), min(e_right, e_now) - e)  # (S, T - 1) [m], > 0 off the road
    excursion = np.where(s <= s_end, out, 0.0).max(axis=1, initial=0.0)  # (S,) [m], 0 where it stays on
    allowed = 0.0 if lane_following is None else excursion[lane_following]
    return excursion <= allowed


def _choose(cfg: PlannerConfig, times, trajectories, omega, frenet, c_vel, c_dist, c_obs, first, dev,
            v_ref, road, obstacles: Obstacles) -> PlanResult:
    """The cheapest feasible sample, on the road where one is (ties to the nearest the nominal one), else
    the ``infeasible_fallback``'s (see the module docstring). ``first``: (S,) each sample's first contact
    step, an index into ``times[1:]`` (``len(times) - 1``: none); ``obstacles``: the problem's."""
    total = cfg.w_velocity * c_vel + cfg.w_dist * c_dist + cfg.w_obs * c_obs
    brake_index = len(total) - 1
    n = len(times) - 1
    feasible = first >= n
    contact_time = np.where(feasible, np.inf, times[1:][np.minimum(first, n - 1)])
    any_feasible = feasible.any()
    if any_feasible:
        chosen = _cheapest(total, feasible & road if (feasible & road).any() else feasible, dev, cfg.tie_tolerance)
    elif cfg.infeasible_fallback == "min_cost":
        chosen = _cheapest(total, np.ones_like(feasible), dev, cfg.tie_tolerance)
    elif cfg.infeasible_fallback == "brake":
        chosen = brake_index
    else:  # latest_contact: the latest first contact; among ties the slowest there if it is met ahead
        step = int(first.max())
        latest = first == step
        impact_speed = np.abs(trajectories[:, step + 1, 3])
        chosen = int(np.argmin(np.where(latest, impact_speed, np.inf)))
        if not met_ahead(trajectories[chosen, step + 1], float(times[step + 1]), obstacles, cfg):
            chosen = _cheapest(total, latest, dev, cfg.tie_tolerance)
    return PlanResult(times=times, trajectories=trajectories, omega=omega, frenet=frenet,
                      costs=np.stack([c_vel, c_dist, c_obs], axis=1), total=total, feasible=feasible,
                      contact_time=contact_time, on_road=road, chosen=chosen,
                      collision_free=bool(feasible[chosen]), brake_index=brake_index, v_ref=float(v_ref))


def _cheapest(total: np.ndarray, among: np.ndarray, dev: np.ndarray, tolerance: float) -> int:
    """The index of the cheapest sample ``among`` (S,) mask; samples within ``tolerance`` of its ``total``
    count as tied, and the one of smallest ``dev`` (distance from the nominal sample) among them wins."""
    cand = np.where(among, total, np.inf)
    tied = cand <= cand.min() + tolerance
    return int(np.argmin(np.where(tied, dev, np.inf)))


def met_ahead(pose: np.ndarray, t: float, obstacles: Obstacles, cfg: PlannerConfig) -> bool:
    """Whether an obstacle that touches the ego's footprint (inflated by ``safety_margin``) at ``pose`` =
    ``[x, y, yaw, v]`` at time ``t`` [s] (obstacles predicted as the collision check predicts them) has
    its centre ahead of the ego's centre along its heading: a contact that braking puts off or softens.
    One from behind or beside-behind is not: braking in front of it brings it on (a slow lane change
    braked to a stop before the car it left behind was run into), so the fallback then takes the
    cheapest of the samples tied at the latest contact (``docs/experiments/planner-brake-fallback/``)."""
    if len(obstacles) == 0:
        return False
    ox, oy = obstacles.predict(np.array([t]))
    dx, dy = ox[:, 0] - pose[0], oy[:, 0] - pose[1]
    ce, se = math.cos(pose[2]), math.sin(pose[2])
    touches = _sat_overlap(dx, dy, ce, se, 0.5 * cfg.length + cfg.safety_margin, 0.5 * cfg.width + cfg.safety_margin,
                           np.cos(obstacles.yaw), np.sin(obstacles.yaw), 0.5 * obstacles.length,
                           0.5 * obstacles.width)
    return bool((touches & (dx * ce + dy * se > 0.0)).any())


def plan_reference(problem: PlanningProblem, cfg: PlannerConfig | None = None) -> PlanResult:
    """:func:`plan` in numpy around the compiled roll-out and obstacle kernels: the form :func:`plan`'s
    single kernel was written from, which the tests hold it to (equal arrays, the same choice)."""
    cfg = PlannerConfig() if cfg is None else cfg
    ego, path = problem.ego, problem.path
    dt = cfg.dt
    layout = _layout(cfg)
    times = layout.times
    s0, e0, th0, k0 = path.project(ego.xy, ego.yaw, hint_s=problem.s_hint)
    v_ref = min(problem.v_ref, curve_speed_cap(path, s0, ego.v, cfg))

    # ---- samples of v(0), omega(0) and the two braking samples
    v = ego.v
    v_hi = max(v, problem.speed_limit)
    v0 = np.clip(v + layout.dv, 0.0, v_hi)
    lim0 = float(omega_limit(v, cfg.yaw_rate_max, cfg.max_curvature, cfg.lat_accel_max))
    g0 = min(1.0, cfg.gain_speed / max(abs(v), 1e-9))
    w_nom = float(np.clip(control_law(v, k0, e0, th0, cfg.k_theta * g0, cfg.k_e * g0 * g0),
                          -lim0, lim0))
    w0 = w_nom + layout.dw
    n_grid = cfg.n_v * cfg.n_omega
    V0 = np.concatenate([np.repeat(v0, cfg.n_omega), [v, v]])
    W0 = np.concatenate([np.tile(w0, cfg.n_v), [w_nom, w_nom]])
    v_tgt = np.concatenate([np.full(n_grid, v_ref), [0.0, 0.0]])
    V = linear_speed_profile(V0, v_tgt, times, cfg.accel, layout.dec)  # (S, T)
    # normalised distance of each sample from the nominal one (tie-breaking only)
    dev = (np.abs(W0 - w_nom) / max(cfg.omega_spread, 1e-9)
           + np.abs(V0 - v) / max((cfg.accel + cfg.decel) * cfg.v_window_time, 1e-9))
    dev[n_grid:] = (1e6, 2e6)  # braking samples: only when strictly cheapest
    lim = omega_limit(V, cfg.yaw_rate_max, cfg.max_curvature, cfg.lat_accel_max)
    # gain schedule above gain_speed: k_theta ~ 1/|v|, k_e ~ 1/v^2 (same damping ratio)
    gsc = np.minimum(1.0, cfg.gain_speed / np.maximum(np.abs(V), 1e-9))
    KTH = np.ascontiguousarray((cfg.k_theta * gsc).T)
    KE = np.ascontiguousarray((cfg.k_e * gsc * gsc).T)

    # ---- local, uniformly resampled reference for fast windowed projection
    vmax = float(V.max())
    ds = cfg.path_resolution
    # covers everything a sample can reach (extended straight past the path's ends)
    lp = path.resample(ds, s0 - 10.0 - 2 * ds, s0 + vmax * cfg.horizon + 20.0, extrapolate=True)

    # ---- roll-out (compiled: sequential in time, see .rollout; numba loads on the first call)
    from .rollout import roll_out

    hold = layout.hold
    X, Y, PSI, SS, EE, W = roll_out(  # floats, whatever the caller gave: one compiled signature
        float(ego.x), float(ego.y), float(ego.yaw), float(s0), float(e0), float(th0), float(k0),
        np.ascontiguousarray(V.T), KTH, KE, np.ascontiguousarray(lim.T), W0 - w_nom, int(hold), float(dt),
        2, 2,  # +-2 segments of slack
        *lp.uniform_segments())  # (T, S) time-major

    # ---- costs
    Vf = V[:, 1:]
    c_vel = (np.abs(v_ref - Vf) @ layout.t2) / layout.t2_sum
    c_dist = 1.0 / (1.0 + np.abs(Vf).sum(axis=1))
    obs = problem.obstacles
    future = times[1:]
    c_obs = _obstacle_cost(SS[1:], EE[1:], obs, lp, future, cfg)
    first = _first_contacts(X[1:], Y[1:], PSI[1:], collision_checked(obs, lp, s0, e0, cfg), future, cfg)
    frenet = np.stack([SS.T, EE.T], axis=2)
    return _choose(cfg, times, np.stack([X.T, Y.T, PSI.T, V], axis=2), np.ascontiguousarray(W.T),
                   frenet, c_vel, c_dist, c_obs, first, dev, v_ref, on_road(frenet, problem.corridor,
                                                                            layout.lane_following), obs)


def compile_kernels(cfg: PlannerConfig | None = None) -> None:
    """Compile the planning kernel (:func:`.plan_kernel.plan_samples`, with the roll-out and obstacle
    kernels it calls) and the planning package's other compiled paths (:meth:`.frame.Path.project_pose` and
    :meth:`.frame.Path.project_poses`, the tracker's :mod:`.tracking_kernel`), or load them from numba's on-disk
    cache, before :func:`plan` is timed.

    One :func:`plan` on a straight road with one obstacle: ``plan`` passes the kernel the same
    argument types whatever the problem, so this compiles the one signature every later call
    uses. Without it the first ``plan`` of a process includes the compile (seconds).
    """
    path = Path(np.column_stack([np.linspace(0.0, 100.0, 51), np.zeros(51)]))
    obstacles = np.array([[30.0, 0.0, 0.0, 2.0, 4.5, 1.8]])
    ego = VehicleState(10.0, 0.0, 0.0, 5.0)
    result = plan(PlanningProblem(ego=ego, path=path, v_ref=8.0, speed_limit=10.0, obstacles=obstacles), cfg)
    path.project_pose(10.0, 0.0, 0.0, 10.0)  # the executor's finish check
    path.project_poses(np.zeros((1, 2)), np.zeros(1))  # the expert's scene
    from .tracking import TrajectoryTracker

    TrajectoryTracker().control(ego, result.trajectory, result.times, result.times[1])  # its tracker
