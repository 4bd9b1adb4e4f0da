"""What the renderer draws at one instant: a :class:`SceneView` in world coordinates.

World coordinates are the SUMO network's: x east, y north [m]; yaw [rad] counter-clockwise
from +x; every position is a footprint CENTRE. The driving world builds one per simulation
step; tests and figures build them by hand.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hbmp_bench.errors import ConfigError

SIGNAL_STATES = "rRyYuUgGsoO"
"""SUMO signal characters a stop bar can show: r/R red, y/Y amber, u/U red+amber, g/G green
(minor/major), s green right-turn arrow, o/O off (blinking / no signal)."""


def _array(name: str, value, shape: tuple[int | None, ...], dtype=float) -> np.ndarray:
    """``value`` as a read-only array of ``shape`` (None: any length); empty input becomes (0, ...)."""
    arr = np.asarray(value, dtype=dtype)
    if arr.size == 0 and shape[0] in (None, 0):
        arr = arr.reshape((0, *shape[1:]))
    if arr.ndim != len(shape) or any(t is not None and a != t for a, t in zip(arr.shape, shape)):
        want = "(" + ", ".join("K" if t is None else str(t) for t in shape) + ")"
        raise ValueError(f"SceneView.{name} must have shape {want}, got {arr.shape}")
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise ValueError(f"SceneView.{name} must be finite")
    arr = np.array(arr, copy=True)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class SceneView:
    """Everything needed to draw one instant (K actors, S planner samples of T points).

    Attributes:
        ego_xy: (2,) ego footprint centre [m].
        ego_yaw: ego heading [rad].
        ego_length, ego_width: ego footprint [m].
        ego_speed: ego speed [m/s].
        actors_xy: (K, 2) footprint centres of the other vehicles and pedestrians [m].
        actors_yaw: (K,) headings [rad].
        actors_length, actors_width: (K,) footprints [m].
        actors_is_pedestrian: (K,) bool; pedestrians are drawn as dots.
        light_states: incoming controlled lane id -> SUMO signal character (see
            :data:`SIGNAL_STATES`); drawn as a stop bar at the end of that lane.
        route_edges: the ego's route (edge ids), drawn as a translucent band.
        goal_xy: (2,) goal position [m].
        plan_trajectories: (S, T, 2) sampled trajectories ``x, y`` [m] of the motion planner
            (a (S, T, 4) ``x, y, yaw, v`` array, as in ``PlanResult.trajectories``, is cut to
            its first two columns), or None.
        plan_feasible: (S,) bool collision-free mask, or None (all drawn as feasible).
        plan_chosen: index of the chosen sample (drawn thick), or None.
        time_s: simulation time [s].
        caption: text drawn in the top-left corner ("" for none).
    """

    ego_xy: np.ndarray
    ego_yaw: float
    ego_length: float = 4.5
    ego_width: float = 1.8
    ego_speed: float = 0.0
    actors_xy: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    actors_yaw: np.ndarray = field(default_factory=lambda: np.zeros(0))
    actors_length: np.ndarray = field(default_factory=lambda: np.zeros(0))
    actors_width: np.ndarray = field(default_factory=lambda: np.zeros(0))
    actors_is_pedestrian: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    light_states: dict[str, str] = field(default_factory=dict)
    route_edges: tuple[str, ...] = ()
    goal_xy: np.ndarray | None = None
    plan_trajectories: np.ndarray | None = None
    plan_feasible: np.ndarray | None = None
    plan_chosen: int | None = None
    time_s: float = 0.0
    caption: str = ""

    def __post_init__(self):
        put = object.__setattr__
        put(self, "ego_xy", _array("ego_xy", self.ego_xy, (2,)))
        for name in ("ego_yaw", "ego_length", "ego_width", "ego_speed", "time_s"):
            value = float(getattr(self, name))
            if not np.isfinite(value):
                raise ConfigError(f"SceneView.{name} must be finite, got {value!r}")
            put(self, name, value)
        if self.ego_length <= 0 or self.ego_width <= 0:
            raise ConfigError("SceneView.ego_length and ego_width must be > 0 [m]")
        put(self, "actors_xy", _array("actors_xy", self.actors_xy, (None, 2)))
        k = len(self.actors_xy)
        for name in ("actors_yaw", "actors_length", "actors_width"):
            put(self, name, _array(name, getattr(self, name), (k,)))
        put(self, "actors_is_pedestrian", _array("actors_is_pedestrian", self.actors_is_pedestrian, (k,), bool))
        lights = dict(self.light_states)
        for lane, state in lights.items():
            if not isinstance(state, str) or len(state) != 1 or state not in SIGNAL_STATES:
                raise ConfigError(f"SceneView.light_states[{lane!r}] must be one of {SIGNAL_STATES!r}, got {state!r}")
        put(self, "light_states", lights)
        put(self, "route_edges", tuple(self.route_edges))
        if self.goal_xy is not None:
            put(self, "goal_xy", _array("goal_xy", self.goal_xy, (2,)))
        if self.plan_trajectories is None:
            if self.plan_feasible is not None or self.plan_chosen is not None:
                raise ConfigError("SceneView.plan_feasible / plan_chosen need plan_trajectories")
        else:
            plans = np.asarray(self.plan_trajectories, dtype=float)
            if plans.ndim != 3 or plans.shape[2] < 2 or plans.shape[1] < 1:
                raise ConfigError(f"SceneView.plan_trajectories must have shape (S, T, 2), got {plans.shape}")
            plans = _array("plan_trajectories", plans[:, :, :2], (None, plans.shape[1], 2))
            put(self, "plan_trajectories", plans)
            s = len(plans)
            if self.plan_feasible is not None:
                put(self, "plan_feasible", _array("plan_feasible", self.plan_feasible, (s,), bool))
            if self.plan_chosen is not None:
                chosen = int(self.plan_chosen)
                if not 0 <= chosen < s:
                    raise ConfigError(f"SceneView.plan_chosen must be in [0, {s}), got {self.plan_chosen!r}")
                put(self, "plan_chosen", chosen)
        put(self, "caption", str(self.caption))

    @property
    def n_actors(self) -> int:
        return len(self.actors_xy)


def scene_view(world, caption: str = "") -> SceneView:
    """The picture of a driving world's instant, centred on its ego
    (:class:`hbmp_bench.envs.world.DrivingWorld`, read through its public attributes)."""
    ego, net, sim = world.ego, world.net, world.sim
    state, actors, plan = ego.state, ego.actors, ego.driver.last_plan
    return SceneView(
        ego_xy=state.xy, ego_yaw=state.yaw, ego_length=ego.vtype.length, ego_width=ego.vtype.width,
        ego_speed=state.speed, actors_xy=actors.xy, actors_yaw=actors.yaw, actors_length=actors.length,
        actors_width=actors.width, actors_is_pedestrian=actors.is_pedestrian,
        light_states={k: v for k, v in sim.light_states().items() if k in net.lanes},
        route_edges=ego.route.edges, goal_xy=ego.route.goal_xy,
        plan_trajectories=None if plan is None else plan.trajectories[:, :, :2],
        plan_feasible=None if plan is None else plan.feasible,
        plan_chosen=None if plan is None else plan.chosen,
        time_s=sim.time, caption=caption,
    )
