"""A vehicle controlled through the behavior layer: the one implementation for the ego and for
every background agent.

A :class:`ControlledVehicle` owns what one agent's vehicle needs in an episode: its driver (the
fidelity's, :mod:`hbmp_bench.envs.drivers`), the lane it follows, its route keeping, its
infraction detector, its observation (M_t, R_t and the scene) and its reward. Its route is one of

- :class:`GoalRoute` (the ego): the episode's route to its goal, re-planned towards the goal when
  the followed lane cannot continue it; progress along it; R_t's lights are those along the route;
  the privileged scene fields of :mod:`hbmp_bench.envs.privileged` when the world asks for them
  (``WorldConfig.privileged``).
- :class:`LoopRoute` (a background agent): a long chain of random legs, extended before it runs
  out and re-planned from where the lane leads, so the vehicle circulates for the whole episode;
  R_t's light is SUMO's next light on its route.

The world steps SUMO around its vehicles (:class:`hbmp_bench.envs.world.DrivingWorld`)::

    vehicle.begin(action)                    # keep the route, start the behavior (or control step)
    while vehicle.wants_step():              # plan one control period; False once it has finished
        sim.step()
        events = vehicle.after_sim_step(snapshot)   # pose, detectors, end of its episode
    obs, reward, info = vehicle.outcome(events, behavior_ended)
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np

from hbmp_bench.envs.drivers import LANE_CHANGE_CUTOFF_M, feasible_behaviors
from hbmp_bench.envs.observation import ObservationBuilder, road_profile, road_vector
from hbmp_bench.envs.privileged import LIGHTS_RANGE_M, PrivilegedScene
from hbmp_bench.envs.scene import Scene
from hbmp_bench.maps.roadnet import RoadNetwork
from hbmp_bench.metrics.detectors import EVENT_KINDS, EgoFrame, InfractionDetector, StepEvents, StopLine, update_all
from hbmp_bench.metrics.episode import GOAL_UNREACHABLE, EpisodeScorer, carla_rl_reward, events_reward
from hbmp_bench.metrics.geometry import LaneLocator, stop_line_of
from hbmp_bench.planning.behaviors import BEHAVIORS, Behavior
from hbmp_bench.scenarios import Episode
from hbmp_bench.sim.sumo import LEVEL_CLEARANCE_M, Actors, LightAhead, SumoSim, VehicleState, VehicleType

ROUTE_HORIZON_EDGES = 8
"""A circulating vehicle's route is extended when fewer edges than this are left on it."""
NOWHERE = np.array([np.inf, np.inf])
"""Goal of a circulating vehicle: never reached."""
GOAL_CONTINUATION_M = 30.0
"""Route kept past the goal so SUMO does not remove a vehicle that overshoots it [m]."""


@dataclass(frozen=True)
class Shared:
    """What every vehicle of a world shares: the simulation, the network and its helpers.

    ``long_route(rng, edge)`` draws a chain of random legs from ``edge`` (circulating routes)."""

    sim: SumoSim
    net: RoadNetwork
    locator: LaneLocator
    observer: ObservationBuilder
    reward: str
    """``WorldConfig.reward``: dense, sparse or carla."""
    long_route: Callable[[np.random.Generator, str], list[str]]


@dataclass(frozen=True)
class EndRules:
    """When a vehicle's episode ends: at a collision, at any violation (the paper's protocol)."""

    on_collision: bool
    on_violation: bool


def continuation(net: RoadNetwork, edge: str, length_m: float = GOAL_CONTINUATION_M) -> tuple[str, ...]:
    """Edges after ``edge`` (straight where possible), about ``length_m`` [m]. Short on purpose: in
    continuous fidelity SUMO maps a pushed pose onto the route, and a long continuation that comes
    back through a junction of the route could capture the vehicle there."""
    out, total = [], 0.0
    while total < length_m:
        options = net.successors(edge)
        if not options:
            break
        edge = next((e for e in options if net.direction(edge, e) == "s"), options[0])
        out.append(edge)
        total += net.edge_length[edge]
    return tuple(out)


def followed_stop_line(sim: SumoSim, locator: LaneLocator, lane: str, next_edge: str | None) -> StopLine | None:
    """The signalised stop line at the end of the followed ``lane`` on the way to the route's
    ``next_edge``, with its link's signal now (None where that link has no traffic light).

    The detectors judge red lights on it: the lane and route the vehicle follows, not the light
    ahead that SUMO's map matching of a pushed pose reports."""
    fixed = locator.stop_line(lane, next_edge)
    if fixed is None:
        return None
    ends, direction, tls, link_index = fixed
    return StopLine(lane, ends, direction, sim.light_state(tls, link_index))


class ControlledVehicle:
    """One SUMO vehicle driven by an agent through the behavior layer (see the module docstring).

    Args:
        vehicle_id / vtype: the SUMO vehicle (inserted and handed over) and its type.
        driver: the driver of its fidelity.
        shared: the world's simulation, network and helpers.
        route: :class:`GoalRoute` or :class:`LoopRoute`.
        detector: its infraction detector (goal and timeout, or none).
        rules: when its episode ends.
    """

    def __init__(self, vehicle_id: str, vtype: VehicleType, driver, shared: Shared, route: "GoalRoute | LoopRoute",
                 detector: InfractionDetector, rules: EndRules):
        self.id, self.vtype, self.driver, self.shared = vehicle_id, vtype, driver, shared
        self.route, self.detector, self.rules = route, detector, rules
        state = shared.sim.vehicle_state(vehicle_id)
        if state is None:
            raise RuntimeError(f"SUMO did not insert the controlled vehicle {vehicle_id}")
        driver.reset(state)
        self.state: VehicleState = driver.observe(state)
        self.followed_lane = self.state.lane if self.state.lane in shared.net.lanes else ""
        """The vehicle's lane, or inside a junction the last lane before it (junction lanes
        overlap, and SUMO's map matching of a pushed pose may pick any of them)."""
        self.actors: Actors = shared.sim.snapshot().around(vehicle_id)
        self.decisions = 0
        self.end_reason = ""
        """``goal``, ``collision``, ``violation``, ``timeout`` or ``left_network`` once its episode ended."""
        self.behavior = self.executed = Behavior.KEEP
        self.behavior_start_s = shared.sim.time
        self.scene: Scene | None = None
        """The typed scene of the last observation (``info["scene"]`` is its dict)."""
        self.control: list[float] | None = None
        """The last control vector ``[a, s]`` (a driver without behaviors), as given."""
        route.attach(self)
        self._paid = (self.progress_m(), self.state.speed)
        """Route progress [m] and speed [m/s] at the last reward ``carla`` paid."""
        driver.follow(route.begin_lane(), self.next_edges(), self.next_lanes())

    @property
    def front(self) -> np.ndarray:
        """The front bumper (2,) [m]."""
        s = self.state
        return s.xy + self.vtype.length / 2 * np.array([np.cos(s.yaw), np.sin(s.yaw)])

    def next_edges(self, count: int = 3) -> tuple[str, ...]:
        k = self.route.index()
        return self.route.edges[k + 1: k + 1 + count]

    def next_lanes(self, count: int = 3) -> tuple[frozenset[str], ...]:
        """Per edge of :meth:`next_edges`, the route's lanes there (those it can leave the edge by and
        still reach its goal lane: ``RoadNetwork.route_lanes``): the lanes the followed path enters
        where a lane has several links onto the next edge."""
        k = self.route.index()
        return self.route.lane_sets()[k + 1: k + 1 + count]

    # ------------------------------------------------------------------ step
    def begin(self, action) -> None:
        """Start the behavior ``action`` (0..4; an infeasible lane change runs as keep:
        :func:`~hbmp_bench.envs.drivers.feasible_behaviors` at the front bumper's lane position),
        or, for a driver without behaviors, one control step of ``action`` = ``[a, s]``."""
        self.route.keep()
        if self.driver.behaviors:
            self.behavior = Behavior(action)
            feasible = feasible_behaviors(self.shared.net, self.state.lane, self.state.lane_pos)[action]
            command = int(self.behavior if feasible else Behavior.KEEP)
        else:
            self.control, command = [float(a) for a in action], action
        self.executed = Behavior(self.driver.begin(command, self.state, self.route.begin_lane(), self.next_edges(),
                                                   self.next_lanes()))
        self.behavior_start_s = self.shared.sim.time
        self.decisions += 1

    def wants_step(self) -> bool:
        """Let the driver plan one control period; False once the behavior has finished."""
        return self.driver.before_step(self.actors)

    def after_sim_step(self, snapshot: Actors) -> StepEvents:
        """Detection after one simulation step (``snapshot``: every actor now); sets ``end_reason``
        when its episode ends. (The world does this for all its vehicles at once: :func:`after_sim_steps`.)"""
        frame = self.sense(snapshot)
        if frame is None:
            return StepEvents()
        actors = self.actors
        return self.judge(self.detector.update(frame, actors.ids, actors.xy, actors.yaw, actors.length, actors.width,
                                               actors.is_pedestrian, self.shared.sim.time))

    def sense(self, snapshot: Actors) -> EgoFrame | None:
        """The first half of :meth:`after_sim_step`: the new state, followed lane, route progress and
        actors around; the frame the detector judges, or None (``end_reason`` set) when the vehicle has
        left the network."""
        sim, net = self.shared.sim, self.shared.net
        state = sim.vehicle_state(self.id)
        if state is None or self.id in sim.arrived_ids() or self.driver.off_map:
            self.end_reason = "left_network"  # also: driven so far off the road SUMO cannot place it
            return None
        self.state = state = self.driver.observe(state)
        if state.lane in net.lanes and (not self.followed_lane or net.within_reach(self.followed_lane, state.lane)):
            self.followed_lane = state.lane  # (not a jump onto another level: RoadNetwork.within_reach)
        self.route.moved()
        self.actors = snapshot.around(self.id)
        lane = self.followed_lane
        return EgoFrame(state.xy, state.yaw, self.vtype.length, self.vtype.width,
                        followed_stop_line(sim, self.shared.locator, lane, next(iter(self.next_edges(1)), None)),
                        net.lanes[lane].edge if lane in net.lanes else "")

    def judge(self, ev: StepEvents) -> StepEvents:
        """The second half of :meth:`after_sim_step`: ``end_reason`` from the detector's events ``ev``.

        A collision or violation the rules end the episode at outranks the goal reached in the same 0.1 s step (a
        car that reaches its goal off the road has not reached it cleanly): under the paper's protocol a success
        has no violation, as the boards' results check holds (measured: a `flat` episode, hbmp suite
        Town01/Straight/8, crossed its goal in the step it left the road)."""
        if ev.collisions and (self.rules.on_violation or self.rules.on_collision):
            self.end_reason = "collision"
        elif ev.violations and self.rules.on_violation:
            self.end_reason = "violation"
        elif ev.goal_reached:
            self.end_reason = "goal"
        elif ev.timeout:
            self.end_reason = "timeout"
        return ev

    @property
    def terminated(self) -> bool:
        return self.end_reason in ("goal", "violation", "collision", "left_network")

    @property
    def truncated(self) -> bool:
        return self.end_reason == "timeout"

    def action_mask(self) -> np.ndarray:
        """(5,) int8: 1 where a behavior is feasible for R_t."""
        return self.route.action_mask()

    def outcome(self, events: StepEvents, behavior_ended: bool,
                occupancy: np.ndarray | None = None) -> tuple[dict, float, dict]:
        """(observation, reward, info) after ``events``: r_T pays ``events``; r_k (dense reward)
        is paid only when the behavior has ended. ``occupancy``: M_t, when the world built it (see :meth:`observe`)."""
        obs, info = self.observe(events, occupancy)
        r_terminal = events_reward(events, timed_out=self.end_reason in GOAL_UNREACHABLE)
        if behavior_ended:
            self._behavior_info(info)
        if self.shared.reward == "carla":  # paid every step; r_T only logged
            now = (self.progress_m(), self.state.speed)
            reward = carla_rl_reward(now[0] - self._paid[0], now[1] - self._paid[1], events)
            self._paid = now
            info["reward_components"] = {"r_k": 0.0, "r_T": r_terminal, "r_carla": reward}
            return obs, reward, info
        r_k = self.driver.behavior_reward() if behavior_ended else 0.0
        info["reward_components"] = {"r_k": r_k, "r_T": r_terminal}
        return obs, r_terminal + (r_k if self.shared.reward == "dense" else 0.0), info

    def _behavior_info(self, info: dict) -> None:
        """The ended behavior's (or control step's) keys of ``info``."""
        if self.driver.behaviors:
            info["behavior"] = BEHAVIORS[self.behavior]
            info["behavior_executed"] = BEHAVIORS[self.executed]
        else:
            info["control"] = self.control
        info["duration_s"] = round(self.shared.sim.time - self.behavior_start_s, 6)
        info["planner_costs"] = self.driver.behavior_costs()

    def progress_m(self) -> float:
        """Progress along a goal route [m] (0 on a circulating route, which has no goal)."""
        score = getattr(self.route, "score", None)
        return 0.0 if score is None else float(score.progress_m)

    def occupancy_request(self) -> tuple:
        """The arguments of :meth:`ObservationBuilder.occupancy` for M_t now (the world builds every vehicle's
        M_t in one call: :meth:`ObservationBuilder.occupancy_all`)."""
        s, a = self.state, self.actors
        return (s.xy, s.yaw, self.followed_lane or s.lane, self.next_edges(), a.xy, a.yaw, a.length, a.width,
                self.next_lanes())

    def observe(self, events: StepEvents, occupancy: np.ndarray | None = None) -> tuple[dict, dict]:
        """({"occupancy": M_t, "road": R_t}, info) now; ``self.scene`` is the typed scene. ``occupancy``: M_t
        as built from :meth:`occupancy_request` now (None: built here)."""
        road, self.scene = self.route.road_profile()
        road = road_vector(self.shared.observer.config, road, self.scene.stop_distance_m, self.scene.speed_mps)
        extra = self.driver.road_extra()
        if extra.size:
            road = np.concatenate([road.astype(np.float32), extra])
        if occupancy is None:
            occupancy = self.shared.observer.occupancy(*self.occupancy_request())
        info = {
            **({"action_mask": self.action_mask()} if self.driver.behaviors else {}),
            "events": {kind: getattr(events, kind) for kind in EVENT_KINDS},
            "infractions": dict(self.detector.totals),
            "time_s": self.shared.sim.time,
            "scene": self.scene.to_dict(),
        }
        return {"occupancy": occupancy, "road": road}, info



def after_sim_steps(vehicles: list[ControlledVehicle], snapshot: Actors) -> list[StepEvents]:
    """:meth:`ControlledVehicle.after_sim_step` of every vehicle, in order, with their detectors run in
    one pass (:func:`~hbmp_bench.metrics.detectors.update_all`): the same events, states and ends as
    one call per vehicle (tested against it)."""
    frames = [v.sense(snapshot) for v in vehicles]
    judged = [k for k, f in enumerate(frames) if f is not None]
    out = [StepEvents() for _ in vehicles]
    if not judged:
        return out
    at = {actor: k for k, actor in enumerate(snapshot.ids)}
    visible = np.ones((len(judged), len(snapshot)), dtype=bool)
    for row, k in enumerate(judged):  # Actors.around, as a mask
        i = at.get(vehicles[k].id)
        if i is not None:
            visible[row] = np.abs(snapshot.z - snapshot.z[i]) < LEVEL_CLEARANCE_M
            visible[row, i] = False
    events = update_all([vehicles[k].detector for k in judged], [frames[k] for k in judged], snapshot.ids,
                        snapshot.xy, snapshot.yaw, snapshot.length, snapshot.width, snapshot.is_pedestrian, visible,
                        vehicles[0].shared.sim.time)
    for k, ev in zip(judged, events):
        out[k] = vehicles[k].judge(ev)
    return out

class LoopRoute:
    """A circulating route (background agents): see the module docstring.

    Args:
        edges: the route the vehicle was inserted with.
        rng: draws its extensions.
    """

    def __init__(self, edges: tuple[str, ...], rng: np.random.Generator):
        self.edges, self.rng = tuple(edges), rng
        self.v: ControlledVehicle | None = None

    def attach(self, vehicle: ControlledVehicle) -> None:
        self.v = vehicle
        self.moved()

    def index(self) -> int:
        """Index in ``edges`` of its edge (SUMO's route index; the edge before a junction)."""
        return min(max(self.v.state.route_index, 0), len(self.edges) - 1)

    def begin_lane(self) -> str:
        return self.v.followed_lane or self.v.state.lane

    def moved(self) -> None:
        """SUMO's next light on the route, read while the vehicle exists (for R_t)."""
        self.light: LightAhead | None = self.v.shared.sim.light_ahead(self.v.id)

    def _set(self, edges: list[str]) -> None:
        v = self.v
        if v.shared.sim.set_route(v.id, edges):
            self.edges = tuple(edges)
            v.state = dataclasses.replace(v.state, route_index=0)

    def keep(self) -> None:
        """Re-plan from where the lane leads if it does not continue the route; extend a short route."""
        v = self.v
        net, lane, long_route = v.shared.net, v.followed_lane, v.shared.long_route
        if not lane or v.state.lane != lane:
            return
        edge = net.lane(lane).edge
        k = self.index()
        nxt = self.edges[k + 1] if k + 1 < len(self.edges) else None
        if nxt is None or lane not in net.lanes_to(edge, nxt):
            options = net.lane_next.get(lane, ())
            if options:
                self._set([edge, *long_route(self.rng, options[0][1])])
            return
        if len(self.edges) - k < ROUTE_HORIZON_EDGES:
            self._set([*self.edges[k:], *long_route(self.rng, self.edges[-1])[1:]])

    def action_mask(self) -> np.ndarray:
        return feasible_behaviors(self.v.shared.net, self.v.state.lane)

    def _goal_lane(self) -> str:
        """The lane R_t's route lanes lead to: the rightmost of the route's last edge."""
        return self.v.shared.net.edge_lanes[self.edges[-1]][0]

    def lane_sets(self) -> tuple[frozenset[str], ...]:
        """Per route edge, the lanes to leave it by (``RoadNetwork.route_lanes`` to :meth:`_goal_lane`)."""
        return self.v.shared.net.route_lanes(self.edges, self._goal_lane())

    def road_profile(self) -> tuple[np.ndarray, Scene]:
        """R_t (10,) and the scene."""
        v = self.v
        s, net = v.state, v.shared.net
        road, scene = road_profile(net, s.lane, s.lane_pos, self.edges, self.index(), self._goal_lane(), s.speed,
                                   self.light)
        return road, Scene(**scene)


class GoalRoute:
    """The episode's route to its goal (the ego): see the module docstring.

    Args:
        episode: the episode (route, start and goal lanes, goal position, route length).
        fidelity: the driver's (reported in the privileged scene).
        privileged: add the privileged fields to the scene (``WorldConfig.privileged``); without,
            :class:`~hbmp_bench.envs.privileged.PrivilegedScene` is never built nor asked.
    """

    def __init__(self, episode: Episode, fidelity: str, privileged: bool = False):
        self.episode, self.fidelity = episode, fidelity
        self.privileged: PrivilegedScene | None = None
        """Builds the privileged fields of the scene (:mod:`hbmp_bench.envs.privileged`); None: left out."""
        self._wants_privileged = privileged
        self.v: ControlledVehicle | None = None
        self.reroutes = 0

    def attach(self, vehicle: ControlledVehicle) -> None:
        self.v = vehicle
        net, ep = vehicle.shared.net, self.episode
        self.goal_xy = net.position(ep.goal_lane, ep.goal_pos)
        if self._wants_privileged:
            self.privileged = PrivilegedScene(net, vehicle.shared.sim, vehicle.id, vehicle.vtype, self.fidelity,
                                              getattr(vehicle.driver, "lane_path", None))
        self.score = EpisodeScorer(ep.route_length_m, vehicle.state.xy)
        """Distance, progress along the route and the episode record."""
        self._set(ep.route)

    def _set(self, edges: tuple[str, ...]) -> None:
        net, ep = self.v.shared.net, self.episode
        self.edges = tuple(edges)
        self.path = net.route_path(self.edges, ep.start_lane, ep.goal_lane, ep.goal_pos)
        self._lane_sets = net.route_lanes(self.edges, ep.goal_lane, ep.goal_pos)
        self._pos = {e: i for i, e in enumerate(self.edges)}

    def lane_sets(self) -> tuple[frozenset[str], ...]:
        """Per route edge, the lanes to leave it by and still reach the goal lane (``RoadNetwork.route_lanes``)."""
        return self._lane_sets

    def index(self) -> int:
        """Index in ``edges`` of the followed lane's edge (routes never repeat an edge)."""
        lane = self.v.followed_lane
        return self._pos.get(self.v.shared.net.lane(lane).edge, 0) if lane else 0

    def begin_lane(self) -> str:
        return self.v.followed_lane

    def action_mask(self) -> np.ndarray:
        return feasible_behaviors(self.v.shared.net, self.v.state.lane, self.v.state.lane_pos)

    def keep(self) -> None:
        """Re-plan the route when the followed lane cannot continue it.

        A lane without a link onto the route's next edge leads elsewhere once lane changes are
        closed (the last ``LANE_CHANGE_CUTOFF_M`` before the stop line); like a navigation system,
        the route is then re-planned from the edge that lane leads to, so SUMO's route (which
        continuous fidelity maps the vehicle onto) and R_t stay consistent. Costs the agent time
        and route completion, nothing else."""
        v = self.v
        net, lane = v.shared.net, v.followed_lane
        if lane not in net.lanes or v.state.lane != lane:
            return
        if net.lane(lane).length - v.state.lane_pos >= LANE_CHANGE_CUTOFF_M:
            return  # lane changes are still open: the agent can reach a lane that continues the route
        edge = net.lane(lane).edge
        k = self._pos.get(edge)
        if k is None or k + 1 >= len(self.edges) or lane in net.lanes_to(edge, self.edges[k + 1]):
            return
        # the edges this lane leads onto by a link a car may drive (every route takes only those:
        # ``RoadNetwork.links``); a sharper link SUMO has would leave the route without a path
        onto = [to for _, to in net.lane_next.get(lane, ()) if lane in net.lanes_to(edge, to)]
        if not onto:
            return
        goal_edge = self.edges[-1]
        try:
            onward = net.shortest_route(onto[0], goal_edge)
        except (KeyError, ValueError):
            return
        new_route = (*self.edges[:k + 1], *onward)
        if v.shared.sim.set_route(v.id, new_route[k:] + continuation(net, goal_edge)):
            self._set(new_route)
            self.reroutes += 1

    def moved(self) -> None:
        """Distance and progress after a step. Progress [m] = route length − distance still to drive along the current route's lanes,
        junction lanes included (``RoutePath``). On a route edge the front bumper's lane position
        counts; inside the junction after the followed lane's edge, the front bumper's projection
        on the route's junction lanes, so progress runs on through a junction without a jump."""
        v, ep = self.v, self.episode
        net, state = v.shared.net, v.state
        self.score.moved_to(state.xy, v.shared.sim.time, state.speed, state.yaw)
        if state.lane in net.lanes:
            k = self._pos.get(net.lanes[state.lane].edge)
            if k is None:
                return
            at = self.path.position(k, state.lane_pos)
        elif state.lane in net.internal_lanes and v.followed_lane in net.lanes:
            k = self._pos.get(net.lanes[v.followed_lane].edge)
            if k is None or k + 1 >= len(self.edges):
                return
            at = self.path.junction_position(k, v.front)
        else:
            return
        remaining = self.path.position(len(self.edges) - 1, ep.goal_pos) - at
        self.score.progressed_to(ep.route_length_m - remaining)

    # -------------------------------------------------------------- observe
    def road_profile(self) -> tuple[np.ndarray, Scene]:
        """R_t (10,) and the scene: R_t's quantities and the straight-line distance to the goal,
        plus the privileged fields when the world asks for them."""
        v, ep = self.v, self.episode
        ego, net = v.state, v.shared.net
        lights = self._route_lights(first_only=self.privileged is None)
        lane, lane_pos = self._profile_lane()
        road, scene = road_profile(net, lane, lane_pos, self.edges, self.index(), ep.goal_lane, ego.speed,
                                   lights[0] if lights else None, ep.goal_pos)
        goal_distance_m = float(np.hypot(*(ego.xy - self.goal_xy)))
        if self.privileged is None:
            return road, Scene(**scene, goal_distance_m=goal_distance_m)
        privileged = self.privileged.fields(ego, v.followed_lane, v.next_edges(), v.actors, lights,
                                            self._junction_exit_m(), v.next_lanes())
        return road, Scene(**scene, **privileged, goal_distance_m=goal_distance_m,
                           route_lane_light=self._route_lane_light(lane, scene["route_lane_offset"]))

    def _profile_lane(self) -> tuple[str, float]:
        """The lane R_t is read on and the front bumper's position on it [m].

        SUMO's lane as a rule; but a pose pushed with ``moveToXY`` next to the end of a lane may be
        matched onto a junction lane while the front bumper has not reached the stop line yet:
        then the followed lane."""
        v = self.v
        ego, net, lane = v.state, v.shared.net, v.followed_lane
        if ego.lane in net.lanes or lane not in net.lanes:
            return ego.lane, ego.lane_pos
        ahead = self._to_stop_line(lane)
        if ahead <= 0.0:
            return ego.lane, ego.lane_pos
        return lane, max(net.lane(lane).length - ahead, 0.0)

    def _to_stop_line(self, lane: str) -> float:
        """Signed distance [m] from the front bumper to the end of the normal ``lane`` (negative past it)."""
        net = self.v.shared.net
        ends, direction = stop_line_of(net.lane(lane).shape, net.lane(lane).width)
        return float((ends[0] - self.v.front) @ direction)

    def _route_position(self) -> tuple[int | None, float]:
        """(index in the route of the followed lane's edge, distance of the front bumper from the
        route's start along its lanes [m]); (None, nan) off the route."""
        v = self.v
        ego, net = v.state, v.shared.net
        k = self._pos.get(net.lane(v.followed_lane).edge) if v.followed_lane else None
        if k is None:
            return None, float("nan")
        on_edge = ego.lane in net.lanes and net.lanes[ego.lane].edge == self.edges[k]
        if on_edge or k + 1 >= len(self.edges):
            return k, self.path.position(k, ego.lane_pos)
        return k, self.path.junction_position(k, v.front)

    def _junction_exit_m(self) -> float:
        """Distance from the front bumper to the end of the junction the route crosses next, or is
        crossing, along the route's lanes [m] (inf after the last one)."""
        k, at = self._route_position()
        if k is None or k + 1 >= len(self.edges):
            return float("inf")
        return max(float(self.path.edge_start[k + 1]) - at, 0.0)

    def _route_lane_light(self, lane: str, offset: int) -> tuple:
        """Privileged: the light of the link from the lane ``offset`` lanes beside ``lane`` (the one
        that continues the route) onto the route's next edge, as (distance to the stop line [m],
        signal, schedule); () where that lane is ``lane`` itself or its link has no light."""
        v = self.v
        net, sim = v.shared.net, v.shared.sim
        if not offset or lane not in net.lanes:
            return ()
        ids = net.edge_lanes[net.lane(lane).edge]
        here = ids.index(lane)
        if not 0 <= here + offset < len(ids):
            return ()
        fixed = v.shared.locator.stop_line(ids[here + offset], next(iter(v.next_edges(1)), None))
        if fixed is None:
            return ()
        tls, index = fixed[2], fixed[3]
        return (self._to_stop_line(lane), sim.light_state(tls, index), sim.signal_schedule(tls, index))

    def _route_lights(self, first_only: bool = False) -> list[LightAhead]:
        """The traffic lights ahead along the route, nearest first, up to ``LIGHTS_RANGE_M``
        (distance from the front bumper to the stop line [m]); with ``first_only`` the nearest
        alone (R_t's). At the end of the followed lane, its link's (the one the detectors judge),
        also off the route (past a goal it missed, on the route's continuation); beyond, those of
        the links the route takes, and beyond the route's last edge SUMO's next light (not R_t's:
        SUMO's own next lights, ``getNextTLS``, follow SUMO's map matching of a pushed pose, which
        may jump to another visit of a junction; past the route's end there is no other)."""
        v = self.v
        net, sim, lane = v.shared.net, v.shared.sim, v.followed_lane
        if lane not in net.lanes:
            return []
        k, at = self._route_position()
        out = []
        nxt = next(iter(v.next_edges(1)), None)  # the detectors' link (self.edges[k + 1] on the route)
        fixed = v.shared.locator.stop_line(lane, nxt)
        ahead = self._to_stop_line(lane)
        if fixed is not None and ahead > 0.0:
            out.append(LightAhead(fixed[2], fixed[3], ahead, sim.light_state(fixed[2], fixed[3])))
        if nxt is None and not first_only:  # the route's last edge: past a goal it missed, SUMO drives
            light = sim.light_ahead(v.id)  # on along the route's continuation, towards its next light
            if light is not None and all((a.tls, a.link_index) != (light.tls, light.link_index) for a in out):
                out = sorted([*out, light], key=lambda a: a.distance)
        if k is None or nxt is None or (first_only and out):
            return out
        return out + self._lights_beyond(k, at, lane, nxt, first_only)

    def _lights_beyond(self, k: int, at: float, lane: str, nxt: str, first_only: bool) -> list[LightAhead]:
        """The lights of the links the route takes beyond the followed lane's (``k``: its route edge,
        ``at`` [m]: the position along the route), up to ``LIGHTS_RANGE_M``; the nearest alone with
        ``first_only``."""
        net, sim = self.v.shared.net, self.v.shared.sim
        own = next((c for c in net.connections[net.lane(lane).edge] if c.from_lane == lane and c.to_edge == nxt), None)
        to_lane = (own or net.route_link(self.edges[k], nxt, lane)).to_lane
        out = []
        for j in range(k + 1, len(self.edges) - 1):
            distance = float(self.path.edge_end[j]) - at
            if distance > LIGHTS_RANGE_M:
                break
            link = net.route_link(self.edges[j], self.edges[j + 1], to_lane)
            if link.tls:
                out.append(LightAhead(link.tls, link.link_index, distance, sim.light_state(link.tls, link.link_index)))
                if first_only:
                    return out
            to_lane = link.to_lane
        return out
