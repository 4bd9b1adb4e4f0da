"""How one behavior moves one SUMO vehicle: a driver per fidelity, one protocol.

A driver executes one behavior (or, the control driver, one control vector) at a time for one
vehicle; the world steps SUMO around it::

    driver.follow(lane, next_edges, into)                   # at the start: the lane followed (control driver)
    executed = driver.begin(action, state, lane, next_edges, into)   # action: a feasible behavior, or [accel, steer]
    while driver.before_step(others):                       # others: sim.Actors; False once finished
        sim.step()
        state = driver.observe(sim_state)                   # pose the detectors and M_t use
    r_k = driver.behavior_reward()                          # the paper's lambda(c~_total); 0 in event fidelity

The vehicle decides which behavior runs (an infeasible one runs as keep: :func:`feasible_behaviors`,
computed once per decision in :meth:`~hbmp_bench.envs.vehicle.ControlledVehicle.begin`); a driver
runs what it is given and returns the behavior it runs (the planner keeps the lane where the
followed lane has no neighbour: ``planning.executor.target_path``). ``driver.behaviors`` says which kind of action it takes (True: a behavior
index; False: a control vector); ``driver.road_extra()`` the entries it appends to R_t.

- :class:`EventDriver` -- the paper's SUMO stage: SUMO's speed and lane-change commands complete the
  behavior within one decision period.
- :class:`ContinuousDriver` -- the paper's behavior-conditioned sampling motion planner
  (:mod:`hbmp_bench.planning`): replanning and tracking at 10 Hz on a kinematic bicycle model whose
  pose is pushed into SUMO every step (``moveToXY``), so background traffic and pedestrians react to
  it. The behavior lasts until the executor's finish condition holds (variable duration).
- :class:`ControlDriver` -- no behavior layer (the flat baseline): the agent's acceleration and
  steering drive the bicycle model for one 0.1 s step per decision.

:data:`DRIVERS` names them; :func:`make_driver` builds one.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np

from hbmp_bench.envs.observation import LANE_WIDTH_M, followed_path
from hbmp_bench.maps.roadnet import LANE_CHANGE_CUTOFF_M, RoadNetwork
from hbmp_bench.planning import (Behavior, BehaviorConfig, BehaviorExecutor, Control, ExecutorConfig, Obstacles,
                                 PlannerConfig, PlanResult, ReferencePaths, VehicleParams, instant_costs,
                                 reference_speed, reward_from_cost)
from hbmp_bench.planning import VehicleState as ModelState
from hbmp_bench.planning import step as bicycle_step
from hbmp_bench.sim.sumo import Actors, SumoSim, VehicleState, VehicleType


def feasible_behaviors(net: RoadNetwork, lane_id: str, lane_pos: float | None = None) -> np.ndarray:
    """(5,) int8 mask: 1 where a behavior is feasible on ``lane_id``: lane changes need that lane
    and, when the front-bumper position ``lane_pos`` [m] is given, more than
    :data:`LANE_CHANGE_CUTOFF_M` of the lane ahead."""
    mask = np.ones(5, dtype=np.int8)
    mask[Behavior.CHANGE_LEFT] = net.neighbour_lane(lane_id, +1) is not None
    mask[Behavior.CHANGE_RIGHT] = net.neighbour_lane(lane_id, -1) is not None
    if lane_pos is not None and lane_id in net.lanes and net.lane(lane_id).length - lane_pos < LANE_CHANGE_CUTOFF_M:
        mask[Behavior.CHANGE_LEFT] = mask[Behavior.CHANGE_RIGHT] = 0
    return mask


@dataclass(frozen=True)
class ContinuousConfig:
    """Options of the continuous (motion-planner) fidelity.

    Attributes:
        planner: sampling planner parameters (footprint is set from the vehicle type).
        executor: replanning period, finish thresholds and min / max behavior duration.
        vehicle: bicycle-model geometry and actuator limits.
        lane_back_m / lane_ahead_m: reference centreline kept behind / ahead of the lane start [m].
        obstacle_radius_m: actors farther than this from the ego are left out of planning [m].
    """

    planner: PlannerConfig = field(default_factory=PlannerConfig)
    executor: ExecutorConfig = field(default_factory=ExecutorConfig)
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    lane_back_m: float = 20.0
    lane_ahead_m: float = 80.0
    obstacle_radius_m: float = 60.0


class EventDriver:
    """SUMO drives the behavior: v_ref through ``setSpeed``, lane changes through ``changeLane``.

    ``setSpeed`` holds v_ref until the next decision and SUMO moves towards it within the ego
    type's acceleration / deceleration (2.6 / 4.5 m/s², :data:`~hbmp_bench.sim.sumo.EGO_TYPE`;
    the speed mode of :meth:`~hbmp_bench.sim.sumo.SumoSim.hand_over` keeps those limits), so with
    0.1 s decisions one speed step spans several decisions and a chain of speed_down brakes at
    4.5 m/s² (21 m from 50 km/h); with 1 s decisions the speed_down step of
    :class:`~hbmp_bench.planning.BehaviorConfig` keeps it braking the whole decision (23 m).

    Args:
        sim / net: the simulation and its road network.
        vehicle_id: the SUMO vehicle (already handed over, see :meth:`SumoSim.hand_over`).
        steps: simulation steps per behavior.
        behavior: the v_ref rule of speed_up / speed_down.
    """

    def __init__(self, sim: SumoSim, net: RoadNetwork, vehicle_id: str, steps: int, behavior: BehaviorConfig):
        self.sim, self.net, self.vehicle_id = sim, net, vehicle_id
        self.steps, self.behavior_config = steps, behavior
        self._left = 0
        self.last_plan: PlanResult | None = None
        self.off_map = False
        """Whether the vehicle's pose could not be put into SUMO (far off its route): never here."""

    behaviors = True

    def reset(self, state: VehicleState) -> None:
        self._left = 0

    def follow(self, lane: str, next_edges: tuple[str, ...], into: tuple[frozenset[str], ...] = ()) -> None:
        """Nothing to set up: SUMO follows its own lanes."""

    def road_extra(self) -> np.ndarray:
        return _NO_EXTRA

    def begin(self, executed: int, state: VehicleState, lane: str, next_edges: tuple[str, ...],
              into: tuple[frozenset[str], ...] = ()) -> int:
        """Start the (feasible) behavior ``executed``; ``lane`` is the lane followed (SUMO's own lane
        in event fidelity); SUMO picks the links the vehicle takes (``into`` is not used)."""
        limit = self.net.lane(state.lane).speed
        self.sim.set_speed(self.vehicle_id, reference_speed(executed, state.speed, limit, self.behavior_config))
        if executed in (Behavior.CHANGE_LEFT, Behavior.CHANGE_RIGHT):
            side = +1 if executed == Behavior.CHANGE_LEFT else -1
            self.sim.change_lane(self.vehicle_id, self.net.lane(self.net.neighbour_lane(state.lane, side)).index)
        self._left = self.steps
        return executed

    def before_step(self, others: Actors) -> bool:
        if self._left <= 0:
            return False
        self._left -= 1
        return True

    def observe(self, state: VehicleState) -> VehicleState:
        return state

    def behavior_reward(self) -> float:
        return 0.0

    def behavior_costs(self) -> dict[str, float]:
        return {}


class ModelDriver:
    """What every driver of a bicycle model shares: the model's state, taken from SUMO at the
    start, pushed back into SUMO after every step, and reported to the world in place of SUMO's."""

    behaviors = True

    def __init__(self, sim: SumoSim, net: RoadNetwork, vehicle_id: str, config: ContinuousConfig):
        self.sim, self.net, self.vehicle_id, self.config = sim, net, vehicle_id, config
        self.model: ModelState | None = None
        self.last_plan: PlanResult | None = None
        self.off_map = False
        """The model's pose is too far from the route for SUMO to place the vehicle there."""
        self._path = functools.lru_cache(maxsize=512)(
            lambda lane, nxt, into: followed_path(net, lane, nxt, config.lane_back_m, config.lane_ahead_m,
                                                  max_spacing=1.0, round_corners=3, into=into))

    def lane_path(self, lane_id: str, next_edges: tuple[str, ...], into: tuple[frozenset[str], ...] = ()):
        """The (rounded, densified) centreline of ``lane_id`` continued along ``next_edges``, through
        each junction by the link into the route's lanes ``into`` (per next edge, see
        :func:`~hbmp_bench.envs.observation.followed_path`); cached."""
        return self._path(lane_id, tuple(next_edges), tuple(into))

    def reset(self, state: VehicleState) -> None:
        """Take the vehicle's pose from SUMO at the start of an episode (speed kept, steering centred)."""
        self.model = ModelState(float(state.xy[0]), float(state.xy[1]), float(state.yaw), max(float(state.speed), 0.0))
        self.last_plan = None
        self.off_map = False

    def follow(self, lane: str, next_edges: tuple[str, ...], into: tuple[frozenset[str], ...] = ()) -> None:
        """Nothing to set up: each behavior takes its lane when it begins."""

    def road_extra(self) -> np.ndarray:
        return _NO_EXTRA

    def nearby(self, others: Actors) -> Obstacles:
        """The actors within ``config.obstacle_radius_m`` of the model, as planner obstacles."""
        near = np.hypot(others.xy[:, 0] - self.model.x, others.xy[:, 1] - self.model.y) < self.config.obstacle_radius_m
        return obstacles_from(others.xy[near], others.yaw[near], others.speed[near], others.length[near],
                              others.width[near])

    def advance(self, control: Control) -> None:
        """One control period of the bicycle model; the new pose goes into SUMO (``off_map`` when
        SUMO cannot place it), and its speed too: SUMO's drivers judge gaps and the right of way
        at junctions by the vehicle's speed, and a pushed pose alone reads as standing still."""
        self.model = bicycle_step(self.model, control, self.config.executor.dt, self.config.vehicle)
        self.off_map = not self.sim.move_to_xy(self.vehicle_id, self.model.xy, self.model.yaw)
        self.sim.set_speed(self.vehicle_id, self.model.v)

    def observe(self, state: VehicleState) -> VehicleState:
        """SUMO's lane bookkeeping with the model's exact pose and speed."""
        m = self.model
        return dataclasses.replace(state, xy=m.xy, yaw=float(m.yaw), speed=float(m.v))


class ContinuousDriver(ModelDriver):
    """The motion planner drives the behavior on a bicycle model; SUMO only mirrors the pose.

    Args:
        sim / net / vehicle_id: as :class:`EventDriver`.
        vtype: the vehicle's SUMO type (its footprint is the planner's).
        config: planner, executor and vehicle-model options.
        behavior: the v_ref rule of speed_up / speed_down.
    """

    def __init__(self, sim: SumoSim, net: RoadNetwork, vehicle_id: str, vtype: VehicleType,
                 config: ContinuousConfig, behavior: BehaviorConfig):
        super().__init__(sim, net, vehicle_id, config)
        planner = dataclasses.replace(config.planner, length=vtype.length, width=vtype.width,
                                      dt=config.executor.dt)
        self.executor = BehaviorExecutor(planner=planner, config=config.executor, behavior_cfg=behavior,
                                         vehicle=config.vehicle)

    def reference_paths(self, lane_id: str, next_edges: tuple[str, ...],
                        into: tuple[frozenset[str], ...] = ()) -> ReferencePaths:
        """Centrelines of the left, current and right lane, each continued along the route (into its
        lanes ``into``: :meth:`lane_path`), and the road beside the current lane up to its end: bounded
        on a side without a lane (the footprint inside the lane's width), open where there is one."""
        sides = [self.net.neighbour_lane(lane_id, side) for side in (+1, -1)]
        left, right = (None if lane is None else self.lane_path(lane, next_edges, into) for lane in sides)
        lane = self.net.lane(lane_id)
        half = max(lane.width / 2.0 - self.executor.planner_cfg.width / 2.0, 0.0)
        corridor = (-math.inf if right is not None else -half, math.inf if left is not None else half,
                    self.config.lane_back_m + lane.shape_length)
        return ReferencePaths(left, self.lane_path(lane_id, next_edges, into), right, corridor)

    def begin(self, executed: int, state: VehicleState, lane: str, next_edges: tuple[str, ...],
              into: tuple[frozenset[str], ...] = ()) -> int:
        """Start the (feasible) behavior ``executed`` on the centreline of ``lane`` continued along
        ``next_edges`` into the route's lanes ``into`` (in a junction: the lane before it, so the path
        runs through the route's own connection)."""
        refs = self.reference_paths(lane, tuple(next_edges), tuple(into))
        limit = self.net.lane(lane).speed
        return int(self.executor.start(executed, self.model, refs, limit))

    def before_step(self, others: Actors) -> bool:
        """Plan and track one control period among ``others`` (every other actor now, predicted at
        constant velocity); push the new pose into SUMO. False when the behavior has finished."""
        control, plan = self.executor.step(self.model, self.nearby(others))
        self.last_plan = plan
        if self.executor.done:
            return False
        self.advance(control)
        return True

    def behavior_reward(self) -> float:
        """r_k = lambda(c~_total) of the behavior just executed (see :func:`planning.reward_from_cost`)."""
        return float(self.executor.reward())

    def behavior_costs(self) -> dict[str, float]:
        out = self.executor.outcome()
        names = ("c_velocity", "c_dist", "c_obs")
        return {"c_total": out.c_total, **{n: float(c) for n, c in zip(names, out.c_terms)},
                "finish": out.reason}


def obstacles_from(xy: np.ndarray, yaw: np.ndarray, speed: np.ndarray, length: np.ndarray,
                   width: np.ndarray) -> Obstacles:
    """Planner obstacles (constant-velocity prediction) from (K,) actor arrays."""
    return Obstacles(xy[:, 0], xy[:, 1], yaw, speed, length, width)



class ControlDriver(ModelDriver):
    """No behavior layer: one 0.1 s control step per decision on the bicycle model; SUMO mirrors
    the pose. :meth:`begin` takes the agent's ``[a, s]``; the lane followed (for the lane-keeping
    costs and R_t's two error entries, :meth:`road_extra`) is set at the start (:meth:`follow`)
    and at every decision.

    Args:
        sim / net / vehicle_id / vtype / config: as :class:`ContinuousDriver`.
    """

    def __init__(self, sim: SumoSim, net: RoadNetwork, vehicle_id: str, vtype: VehicleType,
                 config: ContinuousConfig):
        super().__init__(sim, net, vehicle_id, config)
        self.planner = dataclasses.replace(config.planner, length=vtype.length, width=vtype.width)
        self.dt = config.executor.dt
        self.path = None
        self._control = Control(0.0, 0.0, 0.0)
        self._left = 0
        self._costs = (0.0, 0.0)

    behaviors = False

    def follow(self, lane: str, next_edges: tuple[str, ...], into: tuple[frozenset[str], ...] = ()) -> None:
        """Follow the centreline of ``lane`` continued along ``next_edges`` (:meth:`lane_path`)."""
        self.path = self.lane_path(lane, next_edges, into)

    def begin(self, control: np.ndarray, state: VehicleState, lane: str, next_edges: tuple[str, ...],
              into: tuple[frozenset[str], ...] = ()) -> int:
        """One control step of ``control`` = ``[a, s]`` (clipped to [-1, 1]): throttle (a > 0) or brake
        (a < 0) fraction, steering fraction (left > 0)."""
        accel, steer = (float(np.clip(a, -1.0, 1.0)) for a in control)
        self._control = Control(steer=steer, throttle=max(accel, 0.0), brake=max(-accel, 0.0))
        self.follow(lane, next_edges, into)
        self._left = 1
        return Behavior.KEEP

    def before_step(self, others: Actors) -> bool:
        if self._left <= 0:
            return False
        self._left -= 1
        self.advance(self._control)
        self._costs = instant_costs(self.path, self.model, self.nearby(others), self.planner)
        return True

    def behavior_reward(self) -> float:
        """r_t = λ(dt·(c_dist + c_obs)) after the step: HBMP's λ (``ExecutorConfig.reward_scale``)
        on the per-second cost, so Σr_t stays on the scale of HBMP's one r_k per ~1 s behavior."""
        cost = self.dt * (self.planner.w_dist * self._costs[0] + self.planner.w_obs * self._costs[1])
        return float(reward_from_cost(cost, self.config.executor.reward_scale))

    def behavior_costs(self) -> dict[str, float]:
        return {"c_dist": self._costs[0], "c_obs": self._costs[1]}

    def road_extra(self) -> np.ndarray:
        """(2,) float32: the lateral error to the followed lane divided by the lane width and the
        heading error divided by π/2, both clipped to [-2, 2] (appended to R_t)."""
        e, th = self.errors()
        return np.clip([e / LANE_WIDTH_M, th / (np.pi / 2)], -2.0, 2.0).astype(np.float32)

    def errors(self) -> tuple[float, float]:
        """Lateral [m] and heading [rad] error of the vehicle to the followed lane."""
        if self.path is None:
            return 0.0, 0.0
        _, e, th, _ = self.path.project(self.model.xy, self.model.yaw)
        return float(e), float(th)


_NO_EXTRA = np.zeros(0, dtype=np.float32)

FIDELITIES = ("event", "continuous")
"""The drivers of the behavior layer."""
DRIVERS = (*FIDELITIES, "control")
"""Every driver a vehicle can have: a fidelity's, or the flat baseline's (``control``)."""


def make_driver(kind: str, sim: SumoSim, net: RoadNetwork, vehicle_id: str, vtype: VehicleType,
                continuous: ContinuousConfig, behavior: BehaviorConfig, steps_per_decision: int):
    """The driver ``kind`` (one of :data:`DRIVERS`) for one vehicle."""
    if kind == "continuous":
        return ContinuousDriver(sim, net, vehicle_id, vtype, continuous, behavior)
    if kind == "control":
        return ControlDriver(sim, net, vehicle_id, vtype, continuous)
    if kind == "event":
        return EventDriver(sim, net, vehicle_id, steps_per_decision, behavior)
    raise ValueError(f"unknown driver {kind!r}; valid: {', '.join(DRIVERS)}")
