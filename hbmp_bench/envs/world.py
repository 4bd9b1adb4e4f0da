"""The driving world: one episode in SUMO with the ego, background traffic, detectors and observations.

Environments (gymnasium, later PettingZoo) are thin shells around this class; it owns the
episode flow so that every shell shares one implementation.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from hbmp_bench import __version__
from hbmp_bench.envs.drivers import FIDELITIES, LANE_CHANGE_CUTOFF_M, ContinuousConfig, ContinuousDriver, EventDriver, feasible_behaviors
from hbmp_bench.envs.observation import ObservationBuilder, ObservationConfig, road_profile
from hbmp_bench.envs.privileged import LIGHTS_RANGE_M, PrivilegedScene
from hbmp_bench.maps import net_path
from hbmp_bench.maps.roadnet import RoadNetwork
from hbmp_bench.metrics.detectors import EVENT_KINDS, EgoFrame, InfractionDetector, StepEvents, StopLine
from hbmp_bench.metrics.geometry import LaneLocator, stop_line_of
from hbmp_bench.metrics.records import EpisodeRecord, driving_score
from hbmp_bench.planning.behaviors import BehaviorConfig
from hbmp_bench.scenarios import Episode, road_network
from hbmp_bench.sim.sumo import EGO_TYPE, Actors, SumoSim

EGO_ID = "ego"
BEHAVIORS = ("speed_up", "speed_down", "change_left", "change_right", "keep")
SPEED_UP, SPEED_DOWN, CHANGE_LEFT, CHANGE_RIGHT, KEEP = range(5)

TERMINAL_REWARD = {
    "goal": 100.0,
    "collision": -50.0,
    "timeout": -50.0,
    "red_light": -10.0,
    "wrong_lane": -1.0,
    "off_road": -1.0,
}
"""The paper's r_T: +100 goal, −50 collision or overtime, −10 red light, −1 wrong lane (off-road
is counted like a wrong lane). Each event pays once, when it happens."""


REWARDS = ("dense", "sparse")
CONTROLLED_SPACING_M = 12.0
"""Least gap between two controlled vehicles inserted on the same lane [m] (SUMO delays an
insertion onto an occupied place; a controlled vehicle must exist from the first step)."""


@dataclass(frozen=True)
class WorldConfig:
    """Options of a driving world.

    Attributes:
        fidelity: ``continuous`` (default: the paper's behavior-conditioned sampling motion planner
            drives a bicycle model whose pose is pushed into SUMO every step; one behavior lasts
            until it converges, 1-8 s) or ``event`` (the paper's SUMO stage: SUMO's speed and
            lane-change commands complete a behavior within ``decision_period_s``).
        reward: ``dense`` (r_k + r_T, HBMP: r_k = lambda(c~_total) of the executed trajectory,
            0 in event fidelity) or ``sparse`` (r_T only, HBMP-S).
        decision_period_s: simulated time per decision in event fidelity [s] (paper: 10 Hz).
        behavior: the v_ref rule of speed_up / speed_down, shared by both fidelities.
        continuous: planner, executor and vehicle-model options of the continuous fidelity.
        observation: M_t grid options.
        background_route_m: length of the chained route each background vehicle gets, long
            enough that it circulates for the whole episode [m].
        step_length_s: SUMO step [s] (the planner's control period in continuous fidelity).
    """

    fidelity: str = "continuous"
    reward: str = "dense"
    decision_period_s: float = 0.1
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    behavior: BehaviorConfig = field(default_factory=BehaviorConfig)
    continuous: ContinuousConfig = field(default_factory=ContinuousConfig)
    background_route_m: float = 4000.0
    step_length_s: float = 0.1

    def __post_init__(self):
        if self.fidelity not in FIDELITIES:
            raise ValueError(f"fidelity must be one of {FIDELITIES}, got {self.fidelity!r}")
        if self.reward not in REWARDS:
            raise ValueError(f"reward must be one of {REWARDS}, got {self.reward!r}")
        if self.decision_period_s < self.step_length_s - 1e-9:
            raise ValueError("decision_period_s must be >= step_length_s")
        if abs(self.continuous.executor.dt - self.step_length_s) > 1e-9:
            raise ValueError("continuous.executor.dt must equal step_length_s (one control period per SUMO step)")

    @property
    def steps_per_decision(self) -> int:
        return max(1, int(round(self.decision_period_s / self.step_length_s)))


class DrivingWorld:
    """One SUMO episode at a time for one town.

    Args:
        town: map name.
        config: world options.
    """

    def __init__(self, town: str, config: WorldConfig):
        self.town = town
        self.config = config
        self.net: RoadNetwork = road_network(town)
        self.locator = LaneLocator(self.net)
        self.observer = ObservationBuilder(self.net, config.observation)
        self.sim = SumoSim(net_path(town), step_length=config.step_length_s)
        if config.fidelity == "continuous":
            self.driver = ContinuousDriver(self.sim, self.net, EGO_ID, EGO_TYPE, config.continuous, config.behavior)
        else:
            self.driver = EventDriver(self.sim, self.net, EGO_ID, config.steps_per_decision, config.behavior)
        self.privileged = PrivilegedScene(self.net, self.sim, EGO_ID, EGO_TYPE, config.fidelity,
                                          getattr(self.driver, "lane_path", None))
        """Builds the privileged fields of ``info["scene"]`` (:mod:`hbmp_bench.envs.privileged`)."""
        self.episode: Episode | None = None
        self.on_substep = None
        """Optional callable run after every simulation step (e.g. to render frames between decisions)."""
        self._reset_state()

    def _reset_state(self) -> None:
        self.decisions = 0
        self.distance_m = 0.0
        self.progress_m = 0.0
        self.done_reason = ""
        self._last_xy: np.ndarray | None = None
        self._ego = None
        self._actors = None
        self._followed_lane = ""

    # --------------------------------------------------------------- episode
    def start(self, episode: Episode, seed: int, controlled: int = 0) -> tuple[dict, dict]:
        """Start ``episode`` with SUMO seed ``seed``; returns the first (observation, info).

        ``controlled``: background vehicles ``bg0``..``bg{controlled-1}`` are handed over to the
        caller (multi-agent world) and inserted where nothing else stands, so all of them exist
        after the first step; 0 (the single-ego env) leaves the traffic exactly as before."""
        if episode.town != self.town:
            raise ValueError(f"episode is in {episode.town}, world is {self.town}")
        self.episode = episode
        self._reset_state()
        rng = np.random.default_rng([episode.seed, seed])
        self.sim.start(seed=int(rng.integers(2**31)))
        start_edge = self.net.lane(episode.start_lane).edge
        self.sim.add_vehicle(
            EGO_ID,
            episode.route + self._continuation(episode.route[-1]),
            lane_index=self.net.lane(episode.start_lane).index,
            pos=episode.start_pos,
            speed=0.0,
            vtype=EGO_TYPE,
        )
        self.sim.hand_over(EGO_ID)
        self.sim.set_speed(EGO_ID, 0.0)
        self._spawn_traffic(rng, start_edge, controlled)
        self.sim.step()
        self._ego = self.sim.vehicle_state(EGO_ID)
        if self._ego is None:
            raise RuntimeError(f"SUMO did not insert the ego for {episode.key}")
        self.driver.reset(self._ego)
        self._ego = self.driver.observe(self._ego)
        self._followed_lane = self._ego.lane
        self._last_xy = self._ego.xy
        self.goal_xy = self.net.position(episode.goal_lane, episode.goal_pos)
        self.detector = InfractionDetector(self.locator, self.goal_xy, episode.success_radius_m, episode.timeout_s)
        self._set_route(episode.route)
        self.reroutes = 0
        self._actors = self.sim.snapshot().around(EGO_ID)
        return self._observe(StepEvents())

    def _continuation(self, edge: str, length_m: float = 30.0) -> tuple[str, ...]:
        """Edges after the goal so SUMO does not remove an ego that overshoots the goal (straight
        where possible). Short on purpose: in continuous fidelity SUMO maps the ego's pose onto
        its route, and a long continuation that comes back through a junction of the route
        could capture the ego there."""
        out, total = [], 0.0
        while total < length_m:
            options = self.net.successors(edge)
            if not options:
                break
            edge = next((e for e in options if self.net.direction(edge, e) == "s"), options[0])
            out.append(edge)
            total += self.net.edge_length[edge]
        return tuple(out)

    def _long_route(self, rng: np.random.Generator, edge: str) -> list[str]:
        route, total = [edge], 0.0
        edges = self.net.drivable_edges
        while total < self.config.background_route_m:
            target = edges[int(rng.integers(len(edges)))]
            if target == route[-1]:
                continue
            dist, prev = self.net.shortest_tree(route[-1])
            if target not in dist:
                continue
            leg = self.net.path_to(prev, route[-1], target)
            route.extend(leg[1:])
            total += dist[target]
        return route

    def _spawn_traffic(self, rng: np.random.Generator, ego_edge: str, controlled: int = 0) -> None:
        traffic = self.episode.traffic
        if controlled > traffic.vehicles:
            raise ValueError(f"{controlled} controlled vehicles asked, the episode has {traffic.vehicles}")
        edges = [e for e in self.net.drivable_edges if e != ego_edge and self.net.edge_length[e] > 15.0]
        taken: dict[str, list[float]] = {}
        self.spawned_routes: dict[str, tuple[str, ...]] = {}
        """Route each controlled background vehicle was inserted with."""
        for k in range(traffic.vehicles):
            for _ in range(100):
                edge = edges[int(rng.integers(len(edges)))]
                lane_ids = self.net.edge_lanes[edge]
                lane = self.net.lanes[lane_ids[int(rng.integers(len(lane_ids)))]]
                route = self._long_route(rng, edge)
                pos = float(rng.uniform(5.0, lane.length - 5.0))
                if k >= controlled or all(abs(pos - p) > CONTROLLED_SPACING_M for p in taken.get(lane.id, ())):
                    break
            else:
                raise RuntimeError(f"no free place for controlled vehicle bg{k} in {self.town}")
            self.sim.add_vehicle(f"bg{k}", route, lane_index=lane.index, pos=pos, speed=0.0)
            if k < controlled:
                self.spawned_routes[f"bg{k}"] = tuple(route)
                taken.setdefault(lane.id, []).append(pos)
                self.sim.hand_over(f"bg{k}")
                self.sim.track_lane(f"bg{k}")
                self.sim.set_speed(f"bg{k}", 0.0)
        walkable = self.net.walkable_edges
        for k in range(traffic.pedestrians if walkable else 0):
            path = [walkable[int(rng.integers(len(walkable)))] for _ in range(5)]
            walks = [(a, b) for a, b in zip(path[:-1], path[1:]) if a != b and self.sim.walk_route_exists(a, b)]
            if not walks:
                continue
            self.sim.add_pedestrian(f"ped{k}", path[0], float(rng.uniform(1.0, self.net.edge_length[path[0]] - 1.0)), walks)

    # ------------------------------------------------------------------ step
    def action_mask(self) -> np.ndarray:
        """(5,) int8: 1 where a behavior is feasible for R_t (lane changes need the target lane)."""
        return feasible_behaviors(self.net, self._ego.lane, self._ego.lane_pos)

    @property
    def followed_lane(self) -> str:
        """The ego's lane, or inside a junction the last lane before it.

        Junction lanes overlap, and SUMO's map matching of a pose pushed with ``moveToXY`` may
        pick any of them; the lane before the junction plus the route's next edges names the
        connection the ego is actually following."""
        return self._followed_lane

    def _route_index(self) -> int:
        """Index in ``self.route`` of the followed lane's edge (routes never repeat an edge)."""
        return self._route_pos.get(self.net.lane(self._followed_lane).edge, 0) if self._followed_lane else 0

    def _next_edges(self, count: int = 3) -> tuple[str, ...]:
        k = self._route_index()
        return self.route[k + 1: k + 1 + count]

    def step(self, behavior: int) -> tuple[dict, float, bool, bool, dict]:
        """Execute one behavior until it finishes or the episode ends.

        Returns (observation, reward, terminated, truncated, info); ``info["duration_s"]`` is the
        simulated time the behavior took.
        """
        self.begin_behavior(behavior)
        total = StepEvents()
        while self.wants_step():
            self.sim.step()
            accumulate(total, self.after_sim_step(self.sim.snapshot()))
            if self.on_substep is not None:
                self.on_substep()
            if self.done_reason:
                break
        return self.outcome(total, behavior_ended=True)

    # The pieces of ``step``, also driven by the multi-agent world (:mod:`hbmp_bench.envs.multi`),
    # which steps SUMO once for all agents between ``wants_step`` and ``after_sim_step``.
    def begin_behavior(self, behavior: int) -> None:
        """Start ``behavior`` (0..4) for the ego."""
        self._keep_route_reachable()
        self._behavior = behavior
        self._executed = self.driver.begin(behavior, self._ego, self._followed_lane, self._next_edges())
        self._behavior_start_s = self.sim.time
        self.decisions += 1

    def wants_step(self) -> bool:
        """Let the driver plan one control period; False once the behavior has finished."""
        return self.driver.before_step(self._actors)

    def outcome(self, events: StepEvents, behavior_ended: bool) -> tuple[dict, float, bool, bool, dict]:
        """(observation, reward, terminated, truncated, info) after ``events`` happened.

        r_T pays ``events``; r_k (dense reward) is paid only when the behavior has ended."""
        obs, info = self._observe(events)
        r_terminal = self._terminal_reward(events)
        r_k = self.driver.behavior_reward() if behavior_ended else 0.0
        if behavior_ended:
            info["behavior"] = BEHAVIORS[self._behavior]
            info["behavior_executed"] = BEHAVIORS[self._executed]
            info["duration_s"] = round(self.sim.time - self._behavior_start_s, 6)
            info["planner_costs"] = self.driver.behavior_costs()
        info["reward_components"] = {"r_k": r_k, "r_T": r_terminal}
        reward = r_terminal + (r_k if self.config.reward == "dense" else 0.0)
        terminated = self.done_reason in ("goal", "violation", "collision", "left_network")
        truncated = self.done_reason == "timeout"
        if terminated or truncated:
            info["episode"] = self.record().to_dict()
        return obs, reward, terminated, truncated, info

    def after_sim_step(self, snapshot: Actors) -> StepEvents:
        """Detection after one simulation step (``snapshot``: every actor now); sets
        ``done_reason`` when the episode ends."""
        state = self.sim.vehicle_state(EGO_ID)
        if state is None or EGO_ID in self.sim.arrived_ids() or self.driver.off_map:
            self.done_reason = "left_network"  # also: driven so far off the road SUMO cannot place it
            return StepEvents()
        state = self.driver.observe(state)
        self._ego = state
        if state.lane in self.net.lanes:
            self._followed_lane = state.lane
        self.distance_m += float(np.hypot(*(state.xy - self._last_xy)))
        self._last_xy = state.xy
        self._update_progress(state)
        actors = snapshot.around(EGO_ID)
        lane = self._followed_lane
        ev = self.detector.update(
            EgoFrame(state.xy, state.yaw, EGO_TYPE.length, EGO_TYPE.width,
                     followed_stop_line(self.sim, self.locator, lane, next(iter(self._next_edges(1)), None)),
                     self.net.lanes[lane].edge if lane in self.net.lanes else ""),
            actors.ids, actors.xy, actors.yaw, actors.length, actors.width, actors.is_pedestrian, self.sim.time,
        )
        self._actors = actors
        ep = self.episode
        if ev.goal_reached:
            self.done_reason = "goal"
        elif ev.collisions and (ep.end_on_violation or ep.end_on_collision):
            self.done_reason = "collision"
        elif ev.violations and ep.end_on_violation:
            self.done_reason = "violation"
        elif ev.timeout:
            self.done_reason = "timeout"
        return ev

    def _update_progress(self, state) -> None:
        """Progress [m] = route length − distance still to drive along the current route's lanes,
        junction lanes included (``RoutePath``). On a route edge the front bumper's lane position
        counts; inside the junction after the followed lane's edge, the front bumper's projection
        on the route's junction lanes, so progress runs on through a junction without a jump."""
        path = self._route_path
        if state.lane in self.net.lanes:
            k = self._route_pos.get(self.net.lanes[state.lane].edge)
            if k is None:
                return
            at = path.position(k, state.lane_pos)
        elif state.lane in self.net.internal_lanes and self._followed_lane in self.net.lanes:
            k = self._route_pos.get(self.net.lanes[self._followed_lane].edge)
            if k is None or k + 1 >= len(self.route):
                return
            front = state.xy + EGO_TYPE.length / 2 * np.array([np.cos(state.yaw), np.sin(state.yaw)])
            at = path.junction_position(k, front)
        else:
            return
        remaining = path.position(len(self.route) - 1, self.episode.goal_pos) - at
        progress = self.episode.route_length_m - remaining
        if progress <= self.episode.route_length_m + 5.0:
            self.progress_m = max(self.progress_m, min(progress, self.episode.route_length_m))

    def _set_route(self, route: tuple[str, ...]) -> None:
        self.route = tuple(route)
        self._route_path = self.net.route_path(self.route, self.episode.start_lane, self.episode.goal_lane,
                                               self.episode.goal_pos)
        self._route_pos = {e: i for i, e in enumerate(self.route)}

    def _keep_route_reachable(self) -> None:
        """Re-plan the route when the followed lane cannot continue it.

        A lane without a link onto the route's next edge leads elsewhere once lane changes are
        closed (the last ``LANE_CHANGE_CUTOFF_M`` before the stop line); like a navigation system,
        the route is then re-planned from the edge that lane leads to, so SUMO's route (which
        continuous fidelity maps the ego onto) and R_t stay consistent. Costs the agent time and
        route completion, nothing else."""
        lane = self._followed_lane
        if lane not in self.net.lanes or self._ego.lane != lane:
            return
        if self.net.lane(lane).length - self._ego.lane_pos >= LANE_CHANGE_CUTOFF_M:
            return  # lane changes are still open: the agent can reach a lane that continues the route
        edge = self.net.lane(lane).edge
        k = self._route_pos.get(edge)
        if k is None or k + 1 >= len(self.route) or lane in self.net.lanes_to(edge, self.route[k + 1]):
            return
        options = self.net.lane_next.get(lane, ())
        if not options:
            return
        out_edge = options[0][1]
        goal_edge = self.route[-1]
        try:
            onward = self.net.shortest_route(out_edge, goal_edge)
        except (KeyError, ValueError):
            return
        new_route = (*self.route[:k + 1], *onward)
        if self.sim.set_route(EGO_ID, new_route[k:] + self._continuation(goal_edge)):
            self._set_route(new_route)
            self.reroutes += 1

    def _terminal_reward(self, ev: StepEvents) -> float:
        return terminal_reward(ev, timed_out=self.done_reason == "timeout")

    # ------------------------------------------------------------- observe
    def _observe(self, events: StepEvents) -> tuple[dict, dict]:
        ego, ep = self._ego, self.episode
        route_index = self._route_index()
        lights = self._route_lights(ego)
        lane, lane_pos = self._profile_lane(ego)
        road, scene = road_profile(self.net, lane, lane_pos, self.route, route_index, ep.goal_lane, ego.speed,
                                   lights[0] if lights else None, ep.goal_pos)
        actors = self._actors
        occupancy = self.observer.occupancy(
            ego.xy, ego.yaw, self._followed_lane or ego.lane, self.route[route_index + 1: route_index + 4],
            actors.xy, actors.yaw, actors.length, actors.width,
        )
        scene["goal_distance_m"] = float(np.hypot(*(ego.xy - self.goal_xy)))
        scene.update(self.privileged.fields(ego, self._followed_lane, self._next_edges(), actors, lights,
                                            self._junction_exit_m(ego)))
        scene["route_lane_light"] = self._route_lane_light(ego, lane, scene["route_lane_offset"])
        info = {
            "action_mask": self.action_mask(),
            "events": {k: getattr(events, k) for k in EVENT_KINDS},
            "infractions": dict(self.detector.totals),
            "time_s": self.sim.time,
            "route_completion": self.route_completion,
            "episode_key": ep.key,
            "scene": scene,
        }
        return {"occupancy": occupancy, "road": road}, info

    def _front(self, ego) -> np.ndarray:
        """The ego's front bumper (2,) [m]."""
        return ego.xy + EGO_TYPE.length / 2 * np.array([np.cos(ego.yaw), np.sin(ego.yaw)])

    def _profile_lane(self, ego) -> tuple[str, float]:
        """The lane R_t is read on and the front bumper's position on it [m].

        SUMO's lane as a rule; but a pose pushed with ``moveToXY`` next to the end of a lane may be
        matched onto a junction lane while the front bumper has not reached the stop line yet:
        then the followed lane."""
        lane = self._followed_lane
        if ego.lane in self.net.lanes or lane not in self.net.lanes:
            return ego.lane, ego.lane_pos
        ahead = self._to_stop_line(ego, lane)
        if ahead <= 0.0:
            return ego.lane, ego.lane_pos
        return lane, max(self.net.lane(lane).length - ahead, 0.0)

    def _to_stop_line(self, ego, lane: str) -> float:
        """Signed distance [m] from the front bumper to the end of the normal ``lane`` (negative past it)."""
        ends, direction = stop_line_of(self.net.lane(lane).shape, self.net.lane(lane).width)
        return float((ends[0] - self._front(ego)) @ direction)

    def _route_position(self, ego) -> tuple[int | None, float]:
        """(index in the route of the followed lane's edge, distance of the front bumper from the
        route's start along its lanes [m]); (None, nan) off the route."""
        k = self._route_pos.get(self.net.lane(self._followed_lane).edge) if self._followed_lane else None
        if k is None:
            return None, float("nan")
        on_edge = ego.lane in self.net.lanes and self.net.lanes[ego.lane].edge == self.route[k]
        path = self._route_path
        if on_edge or k + 1 >= len(self.route):
            return k, path.position(k, ego.lane_pos)
        return k, path.junction_position(k, self._front(ego))

    def _junction_exit_m(self, ego) -> float:
        """Distance from the front bumper to the end of the junction the route crosses next, or is
        crossing, along the route's lanes [m] (inf after the last one)."""
        k, at = self._route_position(ego)
        if k is None or k + 1 >= len(self.route):
            return float("inf")
        return max(float(self._route_path.edge_start[k + 1]) - at, 0.0)

    def _route_lane_light(self, ego, lane: str, offset: int) -> tuple:
        """Privileged: the light of the link from the lane ``offset`` lanes beside ``lane`` (the one
        that continues the route) onto the route's next edge, as (distance to the stop line [m],
        signal, schedule); () where that lane is ``lane`` itself or its link has no light."""
        if not offset or lane not in self.net.lanes:
            return ()
        ids = self.net.edge_lanes[self.net.lane(lane).edge]
        here = ids.index(lane)
        if not 0 <= here + offset < len(ids):
            return ()
        nxt = next(iter(self._next_edges(1)), None)
        fixed = self.locator.stop_line(ids[here + offset], nxt)
        if fixed is None:
            return ()
        tls, index = fixed[2], fixed[3]
        return (self._to_stop_line(ego, lane), self.sim.light_state(tls, index), self.sim.signal_schedule(tls, index))

    def _route_lights(self, ego) -> list[tuple[str, int, float, str]]:
        """The traffic lights ahead along the route the ego follows, nearest first, up to
        ``LIGHTS_RANGE_M``: (tls, link index, distance from the front bumper to the stop line [m],
        signal). At the end of the followed lane, its link's (the one the detectors judge);
        beyond, those of the links the route takes. SUMO's own next lights (``getNextTLS``) follow
        SUMO's map matching of a pushed pose, which may jump to another visit of a junction."""
        k, at = self._route_position(ego)
        lane = self._followed_lane
        if k is None or lane not in self.net.lanes:
            return []
        out = []
        nxt = self.route[k + 1] if k + 1 < len(self.route) else None
        fixed = self.locator.stop_line(lane, nxt)
        ahead = self._to_stop_line(ego, lane)
        if fixed is not None and ahead > 0.0:
            out.append((fixed[2], fixed[3], ahead, self.sim.light_state(fixed[2], fixed[3])))
        if nxt is None:
            return out
        own = next((c for c in self.net.connections[self.net.lane(lane).edge] if c.from_lane == lane and c.to_edge == nxt),
                   None)
        to_lane = (own or self.net.route_link(self.route[k], nxt, lane)).to_lane
        for j in range(k + 1, len(self.route) - 1):
            distance = float(self._route_path.edge_end[j]) - at
            if distance > LIGHTS_RANGE_M:
                break
            link = self.net.route_link(self.route[j], self.route[j + 1], to_lane)
            if link.tls:
                out.append((link.tls, link.link_index, distance, self.sim.light_state(link.tls, link.link_index)))
            to_lane = link.to_lane
        return out

    def scene_view(self, caption: str = ""):
        """What a top-down picture of this instant needs (:class:`hbmp_bench.render.SceneView`)."""
        from hbmp_bench.render.scene import SceneView

        ego, actors, plan = self._ego, self._actors, self.driver.last_plan
        return SceneView(
            ego_xy=ego.xy, ego_yaw=ego.yaw, ego_length=EGO_TYPE.length, ego_width=EGO_TYPE.width,
            ego_speed=ego.speed, actors_xy=actors.xy, actors_yaw=actors.yaw, actors_length=actors.length,
            actors_width=actors.width, actors_is_pedestrian=actors.is_pedestrian,
            light_states={k: v for k, v in self.sim.light_states().items() if k in self.net.lanes},
            route_edges=self.route, goal_xy=self.goal_xy,
            plan_trajectories=None if plan is None else plan.trajectories[:, :, :2],
            plan_feasible=None if plan is None else plan.feasible,
            plan_chosen=None if plan is None else plan.chosen,
            time_s=self.sim.time, caption=caption,
        )

    @property
    def route_completion(self) -> float:
        if self.done_reason == "goal":
            return 1.0
        return float(np.clip(self.progress_m / self.episode.route_length_m, 0.0, 1.0))

    def record(self, agent: str = "") -> EpisodeRecord:
        """The episode record so far (final once the episode has ended)."""
        ep, totals = self.episode, self.detector.totals
        return EpisodeRecord(
            suite=ep.suite, town=ep.town, task=ep.task, episode=ep.index, seed=ep.seed, agent=agent,
            package_version=__version__, fidelity=self.config.fidelity,
            success=self.done_reason == "goal",
            route_completion=round(self.route_completion, 4),
            collision_vehicle=totals["collision_vehicle"], collision_pedestrian=totals["collision_pedestrian"],
            collision_other=0, wrong_lane=totals["wrong_lane"], off_road=totals["off_road"],
            red_light=totals["red_light"], timeout=self.done_reason == "timeout",
            duration_s=round(self.sim.time, 2), distance_m=round(self.distance_m, 2),
            route_length_m=ep.route_length_m, decisions=self.decisions,
            driving_score=round(driving_score(self.route_completion, totals), 3),
            end_reason=self.done_reason or "running",
        )

    def close(self) -> None:
        self.sim.close()


def terminal_reward(ev: StepEvents, timed_out: bool = False) -> float:
    """The paper's r_T of the events ``ev`` (see ``TERMINAL_REWARD``)."""
    r = TERMINAL_REWARD
    return float(
        r["goal"] * ev.goal_reached
        + r["collision"] * ev.collisions
        + r["timeout"] * timed_out
        + r["red_light"] * ev.red_light
        + r["wrong_lane"] * ev.wrong_lane
        + r["off_road"] * ev.off_road
    )


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


def accumulate(total: StepEvents, ev: StepEvents) -> None:
    """Add the events ``ev`` into ``total`` in place (counts add, flags or)."""
    for f in dataclasses.fields(StepEvents):
        value = getattr(ev, f.name)
        merged = (getattr(total, f.name) or value) if isinstance(value, bool) else getattr(total, f.name) + value
        setattr(total, f.name, merged)
