"""The multi-agent driving world: the ego plus background vehicles driven by agents, one SUMO run.

:class:`TrafficWorld` wraps the single-ego :class:`~hbmp_bench.envs.world.DrivingWorld` (which keeps
the ego, the episode rules, the traffic and the pedestrians) and adds a :class:`BackgroundAgent` for
each controlled background vehicle ``bg0``..``bg{N-1}``. The remaining background vehicles stay with
SUMO's own models. Both PettingZoo ``traffic_v0`` and the gymnasium ``BehaviorEnv`` run on
``DrivingWorld``: with no controlled vehicle this world steps exactly like ``DrivingWorld.step``.

Decision timing (variable-length behaviors)::

    step(actions): agents whose behavior has ended begin the behavior of their action
    loop: every agent running a behavior plans one control period (driver.before_step);
          if any agent's behavior has ended -> return
          one SUMO step for all; detectors of every agent
          if the ego's episode ended or an agent crashed -> return

An agent whose behavior is still running at the return has ``decision_required = False``; its
action in the next ``step`` is ignored and its committed control period runs in the next SUMO step.

Background agents circulate: their routes are long chains of random legs, extended whenever fewer
than ``ROUTE_HORIZON_EDGES`` edges are left, and re-planned from where their lane leads when they
are in a lane that does not continue the route (as the ego's). A background agent ends only on its
own collision (terminated; its vehicle is then removed from SUMO) or with the episode (truncated).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hbmp_bench.envs.drivers import ContinuousDriver, EventDriver, feasible_behaviors
from hbmp_bench.envs.world import BEHAVIORS, EGO_ID, DrivingWorld, WorldConfig, accumulate, followed_stop_line, terminal_reward
from hbmp_bench.metrics.detectors import EVENT_KINDS, EgoFrame, InfractionDetector, StepEvents
from hbmp_bench.scenarios import Episode
from hbmp_bench.sim.sumo import BACKGROUND_TYPE, Actors

ROUTE_HORIZON_EDGES = 8
"""A background agent's route is extended when fewer edges than this are left on it."""

NOWHERE = np.array([np.inf, np.inf])
"""Goal of a circulating agent: never reached."""


class BackgroundAgent:
    """One background vehicle driven by an agent through the behavior layer.

    Args:
        world: the world it lives in (simulation, network, observation builder, route maker).
        vehicle_id: its SUMO id (``bgK``), inserted and handed over by ``DrivingWorld.start``.
        fidelity: ``event`` or ``continuous`` (see :class:`~hbmp_bench.envs.world.WorldConfig`).
        rng: draws its route extensions.
    """

    def __init__(self, world: DrivingWorld, vehicle_id: str, fidelity: str, rng: np.random.Generator):
        self.world, self.id, self.rng = world, vehicle_id, rng
        sim, net, cfg = world.sim, world.net, world.config
        if fidelity == "continuous":
            self.driver = ContinuousDriver(sim, net, vehicle_id, BACKGROUND_TYPE, cfg.continuous, cfg.behavior)
        else:
            self.driver = EventDriver(sim, net, vehicle_id, cfg.steps_per_decision, cfg.behavior)
        self.detector = InfractionDetector(world.locator, NOWHERE, 0.0, np.inf)
        self.state = sim.vehicle_state(vehicle_id)
        if self.state is None:
            raise RuntimeError(f"SUMO did not insert the controlled vehicle {vehicle_id}")
        self.driver.reset(self.state)
        self.state = self.driver.observe(self.state)
        self.followed_lane = self.state.lane if self.state.lane in net.lanes else ""
        self.route: tuple[str, ...] = world.spawned_routes[vehicle_id]
        self.light = sim.light_ahead(vehicle_id)
        self.actors = sim.snapshot().around(vehicle_id)
        self.crashed = False
        self.decisions = 0
        self._behavior = self._executed = 4
        self._start_s = sim.time

    # ------------------------------------------------------------------ route
    def _route_index(self) -> int:
        """Index in ``self.route`` of its edge (SUMO's route index; the edge before a junction)."""
        return min(max(self.state.route_index, 0), len(self.route) - 1)

    def _next_edges(self, count: int = 3) -> tuple[str, ...]:
        k = self._route_index()
        return self.route[k + 1: k + 1 + count]

    def _set_route(self, route: list[str]) -> bool:
        if self.world.sim.set_route(self.id, route):
            self.route = tuple(route)
            self.state = dataclasses.replace(self.state, route_index=0)
            return True
        return False

    def _keep_circulating(self) -> None:
        """Re-plan from where the lane leads if it does not continue the route; extend a short route."""
        net, lane = self.world.net, self.followed_lane
        if not lane or self.state.lane != lane:
            return
        edge = net.lane(lane).edge
        k = self._route_index()
        nxt = self.route[k + 1] if k + 1 < len(self.route) else None
        if nxt is None or lane not in net.lanes_to(edge, nxt):
            options = net.lane_next.get(lane, ())
            if options:
                self._set_route([edge, *self.world._long_route(self.rng, options[0][1])])
            return
        if len(self.route) - k < ROUTE_HORIZON_EDGES:
            self._set_route([*self.route[k:], *self.world._long_route(self.rng, self.route[-1])[1:]])

    # ------------------------------------------------------------------ step
    def begin_behavior(self, behavior: int) -> None:
        self._keep_circulating()
        self._behavior = behavior
        self._executed = self.driver.begin(behavior, self.state, self.followed_lane or self.state.lane,
                                           self._next_edges())
        self._start_s = self.world.sim.time
        self.decisions += 1

    def wants_step(self) -> bool:
        return self.driver.before_step(self.actors)

    def after_sim_step(self, snapshot: Actors) -> StepEvents:
        sim, net = self.world.sim, self.world.net
        state = sim.vehicle_state(self.id)
        if state is None:
            self.crashed = True  # left the network: cannot happen while the route is extended
            return StepEvents()
        self.state = self.driver.observe(state)
        if state.lane in net.lanes:
            self.followed_lane = state.lane
        self.light = sim.light_ahead(self.id)
        self.actors = snapshot.around(self.id)
        a, lane = self.actors, self.followed_lane
        ev = self.detector.update(
            EgoFrame(self.state.xy, self.state.yaw, BACKGROUND_TYPE.length, BACKGROUND_TYPE.width,
                     followed_stop_line(sim, self.world.locator, lane, next(iter(self._next_edges(1)), None)),
                     net.lanes[lane].edge if lane in net.lanes else ""),
            a.ids, a.xy, a.yaw, a.length, a.width, a.is_pedestrian, sim.time,
        )
        if ev.collisions:
            self.crashed = True
        return ev

    def action_mask(self) -> np.ndarray:
        return feasible_behaviors(self.world.net, self.state.lane)

    def outcome(self, events: StepEvents, behavior_ended: bool) -> tuple[dict, float, dict]:
        """(observation, reward, info) after ``events``; r_k is paid when the behavior has ended."""
        w, s = self.world, self.state
        k = self._route_index()
        light = None if self.light is None else (self.light.tls, self.light.link_index, self.light.distance,
                                                 self.light.state)
        goal_lane = w.net.edge_lanes[self.route[-1]][0]
        road, scene = _road_profile(w, s, self.route, k, goal_lane, light)
        a = self.actors
        occupancy = w.observer.occupancy(s.xy, s.yaw, self.followed_lane or s.lane, self.route[k + 1: k + 4],
                                         a.xy, a.yaw, a.length, a.width)
        r_terminal = terminal_reward(events)
        r_k = self.driver.behavior_reward() if behavior_ended else 0.0
        info = {
            "action_mask": self.action_mask(),
            "events": {kind: getattr(events, kind) for kind in EVENT_KINDS},
            "infractions": dict(self.detector.totals),
            "time_s": w.sim.time,
            "scene": scene,
            "reward_components": {"r_k": r_k, "r_T": r_terminal},
        }
        if behavior_ended:
            info["behavior"] = BEHAVIORS[self._behavior]
            info["behavior_executed"] = BEHAVIORS[self._executed]
            info["duration_s"] = round(w.sim.time - self._start_s, 6)
        reward = r_terminal + (r_k if w.config.reward == "dense" else 0.0)
        return {"occupancy": occupancy, "road": road}, reward, info


def _road_profile(world: DrivingWorld, state, route, route_index, goal_lane, light):
    from hbmp_bench.envs.observation import road_profile

    return road_profile(world.net, state.lane, state.lane_pos, route, route_index, goal_lane, state.speed, light)


class TrafficWorld:
    """The ego and ``controlled`` background agents in one SUMO episode.

    Args:
        town: map name.
        config: world options; ``config.fidelity`` is the ego's.
        controlled: how many background vehicles (``bg0``..) agents drive.
        background_fidelity: ``event`` (default, one behavior = one decision period) or ``continuous``.
    """

    def __init__(self, town: str, config: WorldConfig, controlled: int, background_fidelity: str = "event"):
        if controlled < 0:
            raise ValueError(f"controlled must be >= 0, got {controlled}")
        if background_fidelity not in ("event", "continuous"):
            raise ValueError(f"background_fidelity must be 'event' or 'continuous', got {background_fidelity!r}")
        self.ego = DrivingWorld(town, config)
        self.controlled = controlled
        self.background_fidelity = background_fidelity
        self.names = (EGO_ID, *(f"bg{k}" for k in range(controlled)))
        self.background: dict[str, BackgroundAgent] = {}
        self.live: list[str] = []
        self.running: set[str] = set()
        self.committed: set[str] = set()

    @property
    def sim(self):
        return self.ego.sim

    def start(self, episode: Episode, seed: int) -> tuple[dict, dict]:
        """Start the episode; returns ({agent: observation}, {agent: info}), all needing a decision."""
        obs, info = self.ego.start(episode, seed, controlled=self.controlled)
        self.background = {
            name: BackgroundAgent(self.ego, name, self.background_fidelity,
                                  np.random.default_rng([episode.seed, seed, k + 1]))
            for k, name in enumerate(self.names[1:])
        }
        self.live = list(self.names)
        self.running, self.committed = set(), set()
        observations, infos = {EGO_ID: obs}, {EGO_ID: info}
        for name, agent in self.background.items():
            observations[name], _, infos[name] = agent.outcome(StepEvents(), behavior_ended=False)
        for name in self.names:
            infos[name]["decision_required"] = True
        return observations, infos

    def _agent(self, name: str):
        return self.ego if name == EGO_ID else self.background[name]

    def needs_decision(self, name: str) -> bool:
        return name in self.live and name not in self.running

    def step(self, actions: dict[str, int]):
        """Begin the behaviors of the agents that need a decision, run until any behavior ends.

        Returns (observations, rewards, terminations, truncations, infos) keyed by the agents live
        before the call; finished agents leave ``live``."""
        for name in self.live:
            if self.needs_decision(name):
                self._agent(name).begin_behavior(int(actions[name]))
                self.running.add(name)
        events = {name: StepEvents() for name in self.live}
        ended: set[str] = set()
        while True:
            for name in self.live:
                if name in self.running and name not in self.committed:
                    if self._agent(name).wants_step():
                        self.committed.add(name)
                    else:
                        self.running.discard(name)
                        ended.add(name)
            if ended:
                break
            self.sim.step()
            snapshot = self.sim.snapshot()
            self.committed.clear()
            for name in self.live:
                accumulate(events[name], self._agent(name).after_sim_step(snapshot))
            if self.ego.on_substep is not None:
                self.ego.on_substep()
            if self.ego.done_reason or any(self.background[n].crashed for n in self.live if n != EGO_ID):
                break
        return self._collect(events, ended)

    def _collect(self, events: dict[str, StepEvents], ended: set[str]):
        obs, rewards, terms, truncs, infos = {}, {}, {}, {}, {}
        for name in self.live:
            if name == EGO_ID:
                o, r, term, trunc, info = self.ego.outcome(events[name], behavior_ended=name in ended)
            else:
                agent = self.background[name]
                o, r, info = agent.outcome(events[name], behavior_ended=name in ended)
                term, trunc = agent.crashed, False
            obs[name], rewards[name], terms[name], truncs[name], infos[name] = o, r, term, trunc, info
        episode_over = terms[EGO_ID] or truncs[EGO_ID] if EGO_ID in terms else True
        for name in list(self.live):
            if episode_over and not terms[name]:
                truncs[name] = True
            infos[name]["decision_required"] = self.needs_decision(name) and not (terms[name] or truncs[name])
            if terms[name] or truncs[name]:
                self.live.remove(name)
                self.running.discard(name)
                self.committed.discard(name)
                if name != EGO_ID and terms[name]:
                    self.sim.remove_vehicle(name)
        return obs, rewards, terms, truncs, infos

    def close(self) -> None:
        self.ego.close()
