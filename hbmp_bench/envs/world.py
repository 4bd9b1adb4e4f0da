"""The driving world: one SUMO episode with the ego and the background agents, each a
:class:`~hbmp_bench.envs.vehicle.ControlledVehicle`, among SUMO's own traffic and pedestrians.

Goal-directed vehicles: the ego and, in a multi-agent episode (``Episode.others``), ``ego1``,
``ego2`` ...: each with its own start, goal and route (:class:`~hbmp_bench.envs.vehicle.GoalRoute`),
infraction detector, end rules and episode record (:meth:`DrivingWorld.record`). The scene runs until
every goal-directed vehicle's episode has ended; one that ends earlier leaves the simulation (it
would stand in the others' way at its goal). A single-ego episode is the case of one. A trainer may put
a vehicle whose episode ended back into the scene with a new start, goal and route
(:meth:`DrivingWorld.respawn`), so the scene stays full.

The world owns the simulation's lifecycle, the spawning of traffic and the one step loop every
env runs (the single-ego env is this loop with no background agent)::

    step(actions): vehicles whose behavior has ended begin the behavior of their action
    loop: every vehicle running a behavior plans one control period (vehicle.wants_step);
          if any behavior has ended -> return
          one SUMO step for all; detectors of every vehicle; on_substep()
          if a goal-directed vehicle's episode ended or a background vehicle's did -> return

A vehicle whose behavior is still running at the return needs no decision; its committed control
period runs in the next SUMO step. A vehicle's last step (its episode ended, or the scene's did) pays
the r_k of the behavior it was cut in.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from hbmp_bench import __version__
from hbmp_bench.envs.config import WorldConfig
from hbmp_bench.envs.drivers import make_driver
from hbmp_bench.envs.observation import ObservationBuilder
from hbmp_bench.envs.vehicle import (ControlledVehicle, EndRules, GoalRoute, LoopRoute, NOWHERE, Shared,
                                     after_sim_steps, continuation)
from hbmp_bench.maps import net_path
from hbmp_bench.metrics.detectors import InfractionDetector, StepEvents
from hbmp_bench.metrics.episode import EpisodeId, add_events
from hbmp_bench.metrics.geometry import LaneLocator
from hbmp_bench.envs.registration import RECORD_KEY
from hbmp_bench.metrics.records import DECISION_CAP, EpisodeRecord
from hbmp_bench.scenarios import Episode, episode_entropy, road_network
from hbmp_bench.scenarios.scenario_types import SCRIPT_ACTOR_PREFIX, Script, script_for
from hbmp_bench.sim.sumo import BACKGROUND_TYPE, EGO_TYPE, SumoSim, VehicleType

EGO_ID = "ego"


def goal_vehicle_ids(count: int) -> tuple[str, ...]:
    """The ids of ``count`` goal-directed vehicles: ``ego``, ``ego1``, ``ego2`` ..."""
    return (EGO_ID, *(f"{EGO_ID}{k}" for k in range(1, count)))
LIGHT_STREAM = 0x4C49474854
"""Last entropy word of the light phases' stream in a salted episode (apart from the traffic's)."""
GRIDLOCK_WAIT_S = 30.0
"""A vehicle SUMO drives that has stood this long inside a junction leaves the simulation [s]
(``SumoSim.clear_junction_blockers``: a gridlock with the agents' vehicles), checked every
:data:`GRIDLOCK_CHECK_STEPS` steps."""
GRIDLOCK_CHECK_STEPS = 10
CONTROLLED_SPACING_M = 12.0
"""Least gap between two controlled vehicles inserted on the same lane [m] (SUMO delays an
insertion onto an occupied place; a controlled vehicle must exist from the first step)."""


class DrivingWorld:
    """One SUMO episode at a time for one town (see the module docstring).

    Args:
        town: map name.
        config: world options.
    """

    def __init__(self, town: str, config: WorldConfig):
        self.town, self.config = town, config
        self.net = road_network(town)
        self.locator = LaneLocator(self.net)
        self.observer = ObservationBuilder(self.net, config.observation)
        self.sim = SumoSim(net_path(town), step_length=config.step_length_s)
        self.goal_driver = "control" if config.ego_driver == "control" else config.fidelity
        """The driver kind of every goal-directed vehicle (:data:`~hbmp_bench.envs.drivers.DRIVERS`)."""
        self.ego_driver = self.make_driver(EGO_ID, EGO_TYPE, self.goal_driver)
        """The ego's driver (kept across episodes; every other vehicle gets a new one each episode)."""
        self.episode: Episode | None = None
        self.ego: ControlledVehicle | None = None
        self.vehicles: dict[str, ControlledVehicle] = {}
        self.live: list[str] = []
        """The vehicles whose episode runs, ego first."""
        self.goal_ids: tuple[str, ...] = ()
        """The goal-directed vehicles of the episode: ``ego`` and ``ego1`` ... (``Episode.others``)."""
        self._ended_at: dict[str, float] = {}
        self._agent_contacts: dict[str, set[str]] = {}
        self._arriving: dict[str, Episode] = {}
        self._started_at: dict[str, float] = {}
        self.cleared = 0
        """Vehicles SUMO drove that the episode took out of a gridlock (:data:`GRIDLOCK_WAIT_S`)."""
        self._running: set[str] = set()
        self._committed: set[str] = set()
        self.spawned: tuple[int, int] = (0, 0)
        self.script: Script | None = None
        """The scripted actors of a scenario-type episode (``scenarios.scenario_types``), else None."""
        """(background vehicles, pedestrians) put into the simulation at the episode's start."""

    def make_driver(self, vehicle_id: str, vtype: VehicleType, kind: str):
        """The driver ``kind`` (:data:`~hbmp_bench.envs.drivers.DRIVERS`) for one vehicle."""
        cfg = self.config
        return make_driver(kind, self.sim, self.net, vehicle_id, vtype, cfg.continuous, cfg.behavior,
                           cfg.steps_per_decision)

    # --------------------------------------------------------------- episode
    def start(self, episode: Episode, seed: int, controlled: int = 0, salt: str = "") -> tuple[dict, dict]:
        """Start ``episode`` with reset seed ``seed``; returns ({vehicle: observation}, {vehicle: info}).

        ``controlled``: background vehicles ``bg0``..``bg{controlled-1}`` are driven by agents and
        inserted where nothing else stands, so all of them exist after the first step; 0 leaves
        the traffic exactly as SUMO's.

        Every random stream of the run (SUMO's seed, where each background vehicle and pedestrian
        starts and goes) draws from ``scenarios.episode_entropy(episode.seed, seed, salt)``. A
        ``salt`` (a salted evaluation's secret, see ``evaluation.salting``) changes all of them and
        also starts each traffic light's fixed-time program at a random point of its cycle
        (:data:`LIGHT_STREAM`); the start, goal and route stay the episode's. "" runs the public
        episode exactly as before salting existed."""
        if episode.town != self.town:
            raise ValueError(f"episode is in {episode.town}, world is {self.town}")
        if controlled > episode.traffic.vehicles:
            raise ValueError(f"{controlled} controlled vehicles asked, the episode has {episode.traffic.vehicles}")
        self.episode = episode
        entropy = episode_entropy(episode.seed, seed, salt)
        rng = np.random.default_rng(entropy)
        self.sim.start(seed=int(rng.integers(2**31)))
        if salt:
            lights = np.random.default_rng([*entropy, LIGHT_STREAM])
            self.sim.shift_light_phases({tls: float(lights.random()) for tls in sorted(self.sim.light_ids())})
        self.goal_ids = goal_vehicle_ids(len(episode.agents))
        for name, leg in zip(self.goal_ids, episode.agents):
            start = self.net.lane(leg.start_lane)
            self.sim.add_vehicle(name, leg.route + continuation(self.net, leg.route[-1]), lane_index=start.index,
                                 pos=leg.start_pos, speed=0.0, vtype=EGO_TYPE)
            self.sim.hand_over(name)
            self.sim.set_speed(name, 0.0)
        routes = self._spawn_traffic(rng, {self.net.lane(leg.start_lane).edge for leg in episode.agents}, controlled)
        self.script = script_for(episode, self.net, entropy)
        if self.script is not None:
            self.script.start(self.sim)
        self.sim.step()
        shared = Shared(self.sim, self.net, self.locator, self.observer, self.config.reward, self.long_route)
        self.vehicles = {}
        for name, leg in zip(self.goal_ids, episode.agents):
            if self.sim.vehicle_state(name) is None:
                raise RuntimeError(f"SUMO did not insert the goal-directed vehicle {name} of {episode.key}")
            driver = self.ego_driver if name == EGO_ID else self.make_driver(name, EGO_TYPE, self.goal_driver)
            self.vehicles[name] = ControlledVehicle(
                name, EGO_TYPE, driver, shared, GoalRoute(leg, self.config.fidelity, self.config.privileged),
                InfractionDetector(self.locator, self.net.position(leg.goal_lane, leg.goal_pos), leg.success_radius_m,
                                   leg.timeout_s),
                EndRules(on_collision=leg.end_on_collision, on_violation=leg.end_on_violation))
        self.ego = self.vehicles[EGO_ID]
        for k, (name, route) in enumerate(routes.items()):
            self.vehicles[name] = ControlledVehicle(
                name, BACKGROUND_TYPE, self.make_driver(name, BACKGROUND_TYPE, self.config.background_fidelity),
                shared, LoopRoute(route, np.random.default_rng([*entropy, k + 1])),
                InfractionDetector(self.locator, NOWHERE, 0.0, np.inf), EndRules(on_collision=True, on_violation=False))
        self.live = list(self.vehicles)
        self._running, self._committed = set(), set()
        self._ended_at, self._agent_contacts = {}, {name: set() for name in self.goal_ids}
        self._steps, self.cleared, self._arriving, self._started_at = 0, 0, {}, {}
        agents = frozenset(self.vehicles)
        self._kept = lambda vehicle_id: vehicle_id in agents or vehicle_id.startswith(SCRIPT_ACTOR_PREFIX)
        observations, infos = {}, {}
        for name in self.live:
            observations[name], _, infos[name] = self._outcome(name, StepEvents(), behavior_ended=False)
            infos[name]["decision_required"] = True
        return observations, infos

    def long_route(self, rng: np.random.Generator, edge: str) -> list[str]:
        """A chain of random legs from ``edge``, at least ``config.background_route_m`` long, or up to
        an edge from which no link a car can drive leads on (routes take no link sharper than
        ``SHARPEST_TURN_RADIUS_M``, which leaves dead ends in real towns: CARLA's Town07 has 3-5)."""
        route, total = [edge], 0.0
        edges = self.net.drivable_edges
        while total < self.config.background_route_m:
            target = edges[int(rng.integers(len(edges)))]
            if target == route[-1]:
                continue
            dist, prev = self.net.shortest_tree(route[-1])
            if target not in dist:
                if len(dist) == 1:  # a dead end: nothing else is reachable
                    break
                continue
            route.extend(self.net.path_to(prev, route[-1], target)[1:])
            total += dist[target]
        return route

    def _spawn_traffic(self, rng: np.random.Generator, start_edges: set[str],
                       controlled: int) -> dict[str, tuple[str, ...]]:
        """Insert the episode's background vehicles and pedestrians, none on the goal-directed vehicles'
        ``start_edges``; returns the routes of the controlled ones (handed over, tracked and standing)."""
        traffic = self.episode.traffic
        edges = [e for e in self.net.drivable_edges if e not in start_edges and self.net.edge_length[e] > 15.0
                 and self.net.successors(e)]
        taken: dict[str, list[float]] = {}
        routes: dict[str, tuple[str, ...]] = {}
        for k in range(traffic.vehicles):
            for _ in range(100):
                edge = edges[int(rng.integers(len(edges)))]
                lane_ids = self.net.edge_lanes[edge]
                lane = self.net.lanes[lane_ids[int(rng.integers(len(lane_ids)))]]
                route = self.long_route(rng, edge)
                pos = float(rng.uniform(5.0, lane.length - 5.0))
                if k >= controlled or all(abs(pos - p) > CONTROLLED_SPACING_M for p in taken.get(lane.id, ())):
                    break
            else:
                raise RuntimeError(f"no free place for controlled vehicle bg{k} in {self.town}")
            self.sim.add_vehicle(f"bg{k}", route, lane_index=lane.index, pos=pos, speed=0.0)
            if k < controlled:
                routes[f"bg{k}"] = tuple(route)
                taken.setdefault(lane.id, []).append(pos)
                self.sim.hand_over(f"bg{k}")
                self.sim.track_lane(f"bg{k}")
                self.sim.set_speed(f"bg{k}", 0.0)
        walkable = self.net.walkable_edges
        pedestrians = 0
        for k in range(traffic.pedestrians if walkable else 0):
            path = [walkable[int(rng.integers(len(walkable)))] for _ in range(5)]
            walks = [(a, b) for a, b in zip(path[:-1], path[1:]) if a != b and self.sim.walk_route_exists(a, b)]
            if walks:
                self.sim.add_pedestrian(f"ped{k}", path[0], float(rng.uniform(1.0, self.net.edge_length[path[0]] - 1.0)),
                                        walks)
                pedestrians += 1
        self.spawned = (traffic.vehicles, pedestrians)
        return routes

    # ------------------------------------------------------------------ step
    def needs_decision(self, name: str) -> bool:
        return name in self.live and name not in self._running

    def step(self, actions: dict[str, Any], on_substep: Callable[[], None] | None = None, last: bool = False):
        """Begin the behaviors of the vehicles that need a decision, run until any behavior ends
        (``on_substep`` is called after every SUMO step). ``last``: the step ends the episode of
        every vehicle still live (truncated; the ego's record says ``decision_cap``), a trainer's
        step cap.

        Returns (observations, rewards, terminations, truncations, infos) keyed by the vehicles live
        before the call; finished vehicles leave ``live``."""
        for name in self.live:
            if self.needs_decision(name):
                self.vehicles[name].begin(actions[name])
                self._running.add(name)
        events = {name: StepEvents() for name in self.live}
        ended: set[str] = set()
        while True:
            for name in self.live:
                if name in self._running and name not in self._committed:
                    if self.vehicles[name].wants_step():
                        self._committed.add(name)
                    else:
                        self._running.discard(name)
                        ended.add(name)
            if ended:
                break
            self.sim.step()
            if self.script is not None:
                self.script.tick(self.sim, self.sim.vehicle_state(EGO_ID))
            self._steps += 1
            if self._steps % GRIDLOCK_CHECK_STEPS == 0:
                self.cleared += len(self.sim.clear_junction_blockers(self._kept, GRIDLOCK_WAIT_S))
            admitted = self._admit(events) if self._arriving else ()
            snapshot = self.sim.snapshot()
            self._committed.clear()
            for name, step_events in zip(self.live, after_sim_steps([self.vehicles[n] for n in self.live], snapshot)):
                add_events(events[name], step_events)
                if step_events.collided_with and name in self._agent_contacts:
                    self._agent_contacts[name].update(a for a in step_events.collided_with if a in self._agent_contacts)
            if on_substep is not None:
                on_substep()
            if admitted or any(self.vehicles[name].end_reason for name in self.live):
                break
        if last:
            for name in self.goal_ids:
                if not self.vehicles[name].end_reason:
                    self.vehicles[name].end_reason = DECISION_CAP
        return self._collect(events, ended)

    def start_is_free(self, leg: Episode, clearance_m: float = CONTROLLED_SPACING_M) -> bool:
        """No vehicle stands within ``clearance_m`` [m] of ``leg``'s start (SUMO would delay an insertion there)."""
        actors = self.sim.snapshot()
        xy = self.net.position(leg.start_lane, leg.start_pos)
        cars = actors.xy[~np.asarray(actors.is_pedestrian, dtype=bool)]
        return not len(cars) or float(np.min(np.hypot(*(cars - xy).T))) > clearance_m

    def respawn(self, name: str, leg: Episode) -> None:
        """Put the goal-directed vehicle ``name``, whose episode has ended, back at the start of ``leg``: a new
        episode of its own (start, goal, route, timeout, rules; its ``others`` and traffic are ignored) under the
        same id. SUMO inserts it at the next simulation step; the :meth:`step` that does so returns with its first
        observation (``decision_required``). Choose a free start (:meth:`start_is_free`)."""
        if name not in self._agent_contacts or name in self.live or name in self._arriving:
            raise ValueError(f"{name!r} is not a goal-directed vehicle whose episode has ended")
        self.sim.remove_vehicle(name)
        start = self.net.lane(leg.start_lane)
        self.sim.add_vehicle(name, leg.route + continuation(self.net, leg.route[-1]), lane_index=start.index,
                             pos=leg.start_pos, speed=0.0, vtype=EGO_TYPE)
        self.sim.hand_over(name)
        self.sim.set_speed(name, 0.0)
        self._arriving[name] = leg

    def _admit(self, events: dict[str, StepEvents]) -> tuple[str, ...]:
        """The respawned vehicles SUMO has inserted, each a new :class:`ControlledVehicle` of its leg, live."""
        admitted = []
        for name, leg in list(self._arriving.items()):
            state = self.sim.vehicle_state(name)
            if state is None or not state.lane:  # not on the road yet: SUMO waits for room to insert it
                continue
            del self._arriving[name]
            old = self.vehicles[name]
            driver = old.driver if name == EGO_ID else self.make_driver(name, EGO_TYPE, self.goal_driver)
            self.vehicles[name] = ControlledVehicle(
                name, EGO_TYPE, driver, old.shared, GoalRoute(leg, self.config.fidelity, self.config.privileged),
                InfractionDetector(self.locator, self.net.position(leg.goal_lane, leg.goal_pos), leg.success_radius_m,
                                   self.sim.time + leg.timeout_s),
                EndRules(on_collision=leg.end_on_collision, on_violation=leg.end_on_violation))
            self._agent_contacts[name] = set()
            self._ended_at.pop(name, None)
            self._started_at[name] = self.sim.time
            self.live.append(name)
            events[name] = StepEvents()
            admitted.append(name)
        return tuple(admitted)

    @property
    def over(self) -> bool:
        """Every goal-directed vehicle's episode has ended (the scene's end)."""
        return all(self.vehicles[name].end_reason for name in self.goal_ids)

    def _outcome(self, name: str, events: StepEvents, behavior_ended: bool,
                 occupancy: np.ndarray | None = None) -> tuple[dict, float, dict]:
        obs, reward, info = self.vehicles[name].outcome(events, behavior_ended, occupancy)
        if name in self._agent_contacts:
            info["route_completion"] = self.vehicles[name].route.score.completion(
                self.vehicles[name].end_reason == "goal")
            info["episode_key"] = self.episode.key
        return obs, reward, info

    def _collect(self, events: dict[str, StepEvents], ended: set[str]):
        over = self.over
        obs, rewards, terms, truncs, infos = {}, {}, {}, {}, {}
        grids = self.observer.occupancy_all([self.vehicles[name].occupancy_request() for name in self.live])
        for name, grid in zip(self.live, grids):
            vehicle = self.vehicles[name]
            terms[name] = vehicle.terminated
            truncs[name] = vehicle.truncated or (over and not vehicle.terminated)
            last = terms[name] or truncs[name]
            obs[name], rewards[name], infos[name] = self._outcome(name, events[name], name in ended or last, grid)
        for name in list(self.live):
            infos[name]["decision_required"] = self.needs_decision(name) and not (terms[name] or truncs[name])
            if terms[name] or truncs[name]:
                self.live.remove(name)
                self._running.discard(name)
                self._committed.discard(name)
                goal_directed = name in self._agent_contacts
                if goal_directed:
                    self._ended_at[name] = self.sim.time
                    infos[name][RECORD_KEY] = self.record(vehicle=name).to_dict()
                if (terms[name] and not goal_directed) or (goal_directed and not over):
                    self.sim.remove_vehicle(name)  # a finished vehicle leaves the scene that goes on
        return obs, rewards, terms, truncs, infos

    # ---------------------------------------------------------------- record
    @property
    def route_completion(self) -> float:
        return self.ego.route.score.completion(self.ego.end_reason == "goal")

    def record(self, agent: str = "", vehicle: str = EGO_ID) -> EpisodeRecord:
        """The episode record of the goal-directed ``vehicle`` so far (final once its episode has ended);
        in a multi-agent episode it names the vehicle and the other goal-directed vehicles it collided with
        (``EpisodeRecord.vehicle``, ``agent_collisions``), in a single-ego episode both stay empty."""
        if vehicle not in self._agent_contacts:
            raise ValueError(f"{vehicle!r} is not a goal-directed vehicle of the episode; those are {list(self.goal_ids)}")
        v = self.vehicles[vehicle]
        leg, ep = v.route.episode, self.episode
        record = v.route.score.record(
            EpisodeId(ep.suite, ep.town, ep.task, ep.index, ep.seed, self.config.fidelity, leg.route_length_m),
            agent=agent, package_version=__version__, totals=v.detector.totals, success=v.end_reason == "goal",
            end_reason=v.end_reason,
            duration_s=self._ended_at.get(vehicle, self.sim.time) - self._started_at.get(vehicle, 0.0), decisions=v.decisions,
            traffic=self.spawned)
        if len(self.goal_ids) == 1:
            return record
        return dataclasses.replace(record, vehicle=vehicle,
                                   agent_collisions=" ".join(sorted(self._agent_contacts[vehicle])))

    def records(self, agent: str = "") -> list[EpisodeRecord]:
        """Every goal-directed vehicle's record so far (:meth:`record`), ``ego`` first."""
        return [self.record(agent, name) for name in self.goal_ids]

    def close(self) -> None:
        self.sim.close()
