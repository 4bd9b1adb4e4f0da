"""Scenario types: the hazards of the ``scenarios`` suite, each a route of the town and a script of
real SUMO actors that sets the hazard up around the ego (CARLA Leaderboard / Bench2Drive style).

A scenario type is a task name (``HardBrake``, ``CutIn`` ...) of the records and reports. Its episodes
are drawn like the other suites' (:func:`scenario_episode`: a pure function of the suite seed, the town
and the index), from the routes of its ``pose_task`` on which the hazard fits (``fits``). The world runs
its :class:`Script` (``script_for``): ``start`` once after the ego is inserted, ``tick`` after every SUMO
step. Scripts drive SUMO vehicles and pedestrians through :class:`~hbmp_bench.sim.sumo.SumoSim` only
(inserting them, setting their speeds, lanes and signal obedience, walking a pedestrian across the road);
the ego is never moved. Every script logs what it did and when in ``events`` ((time [s], what)), which
the tests check against where the actors were.

Triggers are set so that a lawful driver can pass: a hazard starts where the ego, at the speed it has,
can still stop (``stopping_room_m``: 1 s of reaction and 3.5 m/s²) unless the hazard is one of keeping a
gap (a leader that brakes: the gap is the ego's to keep).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from hbmp_bench.scenarios.spec import TASK_LABELS, TASKS, Episode

if TYPE_CHECKING:
    from hbmp_bench.maps.roadnet import RoadNetwork
    from hbmp_bench.sim.sumo import SumoSim, VehicleState

WALK_SPEED_MPS = 1.4
"""How fast a scripted pedestrian crosses the road [m/s]."""
REACTION_S = 1.0
COMFORT_DECEL_MPS2 = 3.5


def stopping_room_m(speed_mps: float) -> float:
    """Distance [m] a lawful driver at ``speed_mps`` needs to stop: 1 s of reaction, then 3.5 m/s²."""
    return speed_mps * REACTION_S + speed_mps**2 / (2 * COMFORT_DECEL_MPS2)


SCRIPT_ACTOR_PREFIX = "sc_"
"""Every scripted actor's id begins so (the world never takes them out of a gridlock: the script owns them)."""


class Script:
    """The scripted actors of one episode (see the module docstring).

    Attributes:
        events: (time [s], what) of every step of the hazard, in order.
    """

    def __init__(self, episode: Episode, net: RoadNetwork, rng: np.random.Generator):
        self.episode, self.net, self.rng = episode, net, rng
        self.events: list[tuple[float, str]] = []

    def log(self, sim: SumoSim, what: str) -> None:
        self.events.append((round(sim.time, 2), what))

    def start(self, sim: SumoSim) -> None:
        """Insert what stands or drives from the first step (after the ego's insertion)."""

    def tick(self, sim: SumoSim, ego: VehicleState | None) -> None:
        """Advance the hazard after a SUMO step (``ego``: the ego now, None once it is gone)."""


def _forward(net: RoadNetwork, lane_id: str, pos: float) -> tuple[np.ndarray, np.ndarray]:
    """The point (2,) [m] at ``pos`` of a lane and the lane's unit direction (2,) there."""
    a, b = net.position(lane_id, max(pos - 1.0, 0.0)), net.position(lane_id, pos + 1.0)
    d = b - a
    return net.position(lane_id, pos), d / max(float(np.hypot(*d)), 1e-9)


def _remaining_m(net: RoadNetwork, episode: Episode) -> float:
    """Length [m] of the start edge ahead of the ego's start."""
    return net.edge_length[episode.route[0]] - episode.start_pos


# ------------------------------------------------------------------ HardBrake
class HardBrake(Script):
    """A leader 30 m ahead on the ego's lane and route drives off with SUMO's driver at 70 % of the
    speed limit; once it is faster than 6 m/s and the ego within 18 m behind it (or it has driven
    120 m), it brakes to a stop at 8 m/s², stands 3 s and drives on."""

    LEADER = "sc_leader"
    AHEAD_M = 30.0

    def __init__(self, episode, net, rng):
        super().__init__(episode, net, rng)
        self.phase, self.stopped_at = "follow", math.inf

    def start(self, sim):
        from hbmp_bench.sim.sumo import SCENARIO_TYPE

        ep = self.episode
        sim.add_vehicle(self.LEADER, ep.route, lane_index=self.net.lane(ep.start_lane).index,
                        pos=ep.start_pos + self.AHEAD_M, speed=0.0, vtype=SCENARIO_TYPE)
        sim.track_lane(self.LEADER)
        sim.set_speed(self.LEADER, 0.7 * self.net.lane(ep.start_lane).speed)  # SUMO's driver, lawful below it
        self.start_xy = self.net.position(ep.start_lane, ep.start_pos + self.AHEAD_M)
        self.log(sim, "leader")

    def tick(self, sim, ego):
        leader = sim.vehicle_state(self.LEADER)
        if leader is None or ego is None:
            return
        if self.phase == "follow":
            gap = float(np.hypot(*(leader.xy - ego.xy))) - SCENARIO_LENGTH_M
            driven = float(np.hypot(*(leader.xy - self.start_xy)))
            if leader.speed >= 6.0 and (gap <= 18.0 or driven >= 120.0):
                sim.hand_over(self.LEADER)
                sim.set_speed(self.LEADER, 0.0)
                self.phase = "braking"
                self.log(sim, f"braking from {leader.speed:.1f} m/s, {gap:.1f} m ahead")
        elif self.phase == "braking" and leader.speed < 0.05:
            self.phase, self.stopped_at = "stopped", sim.time
            self.log(sim, "stopped")
        elif self.phase == "stopped" and sim.time >= self.stopped_at + 3.0:
            sim.give_back(self.LEADER)
            self.phase = "gone"
            self.log(sim, "drives on")


# ------------------------------------------------------------------ CutIn
class CutIn(Script):
    """Once the ego is faster than 6 m/s on its start edge, a car appears beside it in the next lane,
    overtakes 3-4 m/s faster and changes into the ego's lane ``gap_m`` (2.5-5 m) ahead of its front bumper,
    then brakes for 2 s to 3 m/s below the ego's speed and drives on with SUMO's driver."""

    CUTTER = "sc_cutter"

    def __init__(self, episode, net, rng):
        super().__init__(episode, net, rng)
        self.gap_m = float(rng.uniform(2.5, 5.0))
        self.extra_mps = float(rng.uniform(3.0, 4.0))
        self.side = _cut_in_side(net, episode)
        self.phase, self.cut_at = "wait", math.inf

    def tick(self, sim, ego):
        from hbmp_bench.sim.sumo import SCENARIO_TYPE

        ep, net = self.episode, self.net
        if ego is None:
            return
        edge = ep.route[0]
        if self.phase == "wait":
            if ego.lane.startswith(":") or net.lane(ego.lane).edge != edge or ego.speed < 6.0:
                return
            if net.edge_length[edge] - ego.lane_pos < 70.0:
                self.phase = "missed"
                self.log(sim, "no room left for the cut-in")
                return
            lane = net.neighbour_lane(ego.lane, self.side)
            if lane is None:
                return
            sim.add_vehicle(self.CUTTER, ep.route[ep.route.index(edge):], lane_index=net.lane(lane).index,
                            pos=max(ego.lane_pos - 6.0, 5.0), speed=ego.speed + self.extra_mps, vtype=SCENARIO_TYPE)
            sim.hand_over(self.CUTTER)
            sim.track_lane(self.CUTTER)
            sim.set_speed(self.CUTTER, ego.speed + self.extra_mps)
            self.phase = "overtake"
            self.log(sim, f"beside, in {lane}")
            return
        cutter = sim.vehicle_state(self.CUTTER)
        if cutter is None:
            return
        if self.phase == "overtake":
            if cutter.lane.startswith(":") or ego.lane.startswith(":"):
                sim.give_back(self.CUTTER)
                self.phase = "missed"
                self.log(sim, "reached the junction before cutting in")
                return
            sim.set_speed(self.CUTTER, ego.speed + self.extra_mps)
            rear_gap = cutter.lane_pos - SCENARIO_LENGTH_M - ego.lane_pos
            if rear_gap >= self.gap_m:
                sim.change_lane(self.CUTTER, net.lane(ego.lane).index)
                sim.set_speed(self.CUTTER, max(ego.speed - 3.0, 0.0))
                self.phase, self.cut_at = "cut", sim.time
                self.log(sim, f"cuts in {rear_gap:.1f} m ahead at {cutter.speed:.1f} m/s (ego {ego.speed:.1f} m/s)")
        elif self.phase == "cut" and sim.time >= self.cut_at + 2.0:
            sim.give_back(self.CUTTER)
            self.phase = "gone"
            self.log(sim, f"drives on in {cutter.lane}")


SCENARIO_LENGTH_M = 4.5
"""Length of a scripted car (``SCENARIO_TYPE``) [m]."""


def _cut_in_side(net: RoadNetwork, episode: Episode) -> int:
    """+1 (from the left) if the start lane has a lane on its left, else -1, 0 if neither."""
    for side in (1, -1):
        if net.neighbour_lane(episode.start_lane, side) is not None:
            return side
    return 0


# ------------------------------------------------------------------ PedestrianStepsOut
class PedestrianStepsOut(Script):
    """A pedestrian stands at the right kerb 70 m ahead of the ego's start; when the ego, at its speed,
    comes within its stopping room and 10 m of that point, they walk across the road at 1.4 m/s (the
    ego's edge and the edge opposite it), and are gone once on the far side."""

    PERSON = "sc_pedestrian"
    AHEAD_M = 70.0

    def __init__(self, episode, net, rng):
        super().__init__(episode, net, rng)
        lanes = net.edge_lanes[episode.route[0]]
        self.at_m = episode.start_pos + self.AHEAD_M
        right = net.lane(lanes[0])
        centre, forward = _forward(net, right.id, self.at_m)
        self.left = np.array([-forward[1], forward[0]])
        width = sum(net.lane(ln).width for ln in lanes)
        opposite = net.opposite.get(episode.route[0])
        if opposite in net.edge_lanes:
            width += sum(net.lane(ln).width for ln in net.edge_lanes[opposite])
        self.kerb = centre - self.left * (right.width / 2 + 0.8)
        self.walk_m = width + 1.6
        self.phase, self.walked = "wait", 0.0

    def start(self, sim):
        sim.add_walker(self.PERSON, self.net.walkable_edges[0], 0.5)
        sim.move_person_to_xy(self.PERSON, self.kerb, math.atan2(self.left[1], self.left[0]))
        self.log(sim, "at the kerb")

    def tick(self, sim, ego):
        yaw = math.atan2(self.left[1], self.left[0])
        if self.phase == "wait":
            sim.move_person_to_xy(self.PERSON, self.kerb, yaw)
            if ego is None or ego.lane.startswith(":") or self.net.lane(ego.lane).edge != self.episode.route[0]:
                return
            ahead = self.at_m - ego.lane_pos
            if ahead <= max(stopping_room_m(ego.speed), 10.0) + 10.0 and ego.speed > 1.0:
                self.phase = "walk"
                self.log(sim, f"steps out {ahead:.1f} m ahead of the ego at {ego.speed:.1f} m/s")
        elif self.phase == "walk":
            self.walked += WALK_SPEED_MPS * sim.step_length
            sim.move_person_to_xy(self.PERSON, self.kerb + self.left * self.walked, yaw)
            if self.walked >= self.walk_m:
                sim.remove_person(self.PERSON)
                self.phase = "gone"
                self.log(sim, "across")


# ------------------------------------------------------------------ junction hazards
@dataclass(frozen=True)
class JunctionHazard:
    """Where a junction hazard happens: the ``k``-th junction of the route (``route[k]`` to
    ``route[k + 1]``), the ego's link there, where the foe link its actors drive crosses it
    (``conflict``, a ``roadnet.LinkConflict``) and ``ahead_m`` [m] from the ego's start to the junction's
    stop line."""

    k: int
    link: object
    conflict: object
    ahead_m: float

    @property
    def foe(self):
        """The foe link (``roadnet.Connection``)."""
        return self.conflict.foe


def _opposite_heading(net: RoadNetwork, edge: str, other: str) -> float:
    """Angle [rad] between the ends of two edges' rightmost lanes as they enter their junction."""
    def end_heading(e):
        shape = net.lane(net.edge_lanes[e][0]).shape
        d = shape[-1] - shape[-2]
        return math.atan2(d[1], d[0])
    a = end_heading(edge) - end_heading(other)
    return abs((a + math.pi) % (2 * math.pi) - math.pi)


def junction_hazard(net: RoadNetwork, episode: Episode, kind: str) -> JunctionHazard | None:
    """The first junction 40-400 m along the route where ``kind`` can happen, None if none:

    - ``unprotected_left``: the ego turns left at a light (link direction ``l``) across the straight
      link of the approach opposite it (within 30 degrees of head-on);
    - ``give_way``: the ego's link has no light and yields (SUMO state ``m``) to a major link (``M``)
      that crosses it;
    - ``merge``: the same, where the major link leads onto the ego's next edge (a ramp or a merge);
    - ``red_light``: the ego goes straight at a light across the straight or left-turn link of an
      approach at 60-120 degrees to its own (at a T junction, the stem's left turn).
    """
    ahead = net.edge_length[episode.route[0]] - episode.start_pos
    for k, (a, b) in enumerate(zip(episode.route[:-1], episode.route[1:])):
        if ahead > 400.0:
            return None
        links = net.links(a, b)
        if ahead >= 40.0 and links:
            for c in net.link_conflicts(links[0]):
                if c.at_m > 0.0 and net.edge_length[c.foe.from_edge] >= 60.0 and \
                        _HAZARD_TESTS[kind](links[0], c.foe, _opposite_heading(net, a, c.foe.from_edge)):
                    return JunctionHazard(k, links[0], c, ahead)
        ahead += net.junction_length(a, b) + net.edge_length[b]
    return None


def _unprotected_left(link, foe, angle: float) -> bool:
    return link.direction == "l" and bool(link.tls) and foe.direction == "s" and angle > math.radians(150)


def _yields(link, foe, merge: bool) -> bool:
    return not link.tls and link.state == "m" and foe.state == "M" and (foe.to_edge == link.to_edge) == merge


def _red_light(link, foe, angle: float) -> bool:
    return link.direction == "s" and bool(link.tls and foe.tls) and foe.direction in "sl" \
        and math.radians(60) < angle < math.radians(120)


_HAZARD_TESTS = {
    "unprotected_left": _unprotected_left,
    "give_way": lambda link, foe, angle: _yields(link, foe, merge=False),
    "merge": lambda link, foe, angle: _yields(link, foe, merge=True),
    "red_light": _red_light,
}
"""Whether the ego's link and a foe link crossing it (with the angle [rad] between their approaches) make
a junction hazard of each kind (:func:`junction_hazard`)."""


def _to_junction_m(net: RoadNetwork, episode: Episode, hazard: JunctionHazard, ego: VehicleState) -> float:
    """Distance [m] from the ego's front bumper to the hazard junction's stop line (negative past it,
    -inf once beyond the junction)."""
    if ego.route_index > hazard.k:
        return -math.inf
    lane_end = net.edge_length[episode.route[ego.route_index]]
    if ego.lane.startswith(":"):
        return 0.0 if ego.route_index == hazard.k else lane_end
    return lane_end - ego.lane_pos + sum(net.edge_length[e] for e in episode.route[ego.route_index + 1:hazard.k + 1])


class CrossTraffic(Script):
    """A stream of ``count`` cars on a foe link of a junction of the route (``hazard_kind``, see
    :func:`junction_hazard`) from when the ego is 100 m from the junction, each after its own headway
    (drawn in ``headway_range``: gaps a driver must judge), inserted 50 m before its stop line at 80 % of its
    lane's limit and driven by SUMO (which keeps its lights and right of way). Subclasses name the hazard
    and draw the stream."""

    hazard_kind = ""
    count_range = (6, 10)
    headway_range = (1.5, 4.0)

    def __init__(self, episode, net, rng):
        super().__init__(episode, net, rng)
        self.hazard = junction_hazard(net, episode, self.hazard_kind)
        self.count = int(rng.integers(self.count_range[0], self.count_range[1] + 1))
        self.headways_s = rng.uniform(*self.headway_range, size=self.count)
        self.sent, self.next_at = 0, math.inf

    def tick(self, sim, ego):
        from hbmp_bench.sim.sumo import SCENARIO_TYPE

        if ego is None or self.hazard is None or self.sent >= self.count:
            return
        net, foe = self.net, self.hazard.foe
        if self.next_at == math.inf:
            if _to_junction_m(net, self.episode, self.hazard, ego) > 100.0:
                return
            self.next_at = sim.time
            self.log(sim, f"stream of {self.count} on {foe.from_lane}, headways "
                          f"{', '.join(f'{h:.1f}' for h in self.headways_s)} s")
        if sim.time + 1e-9 < self.next_at:
            return
        lane = net.lane(foe.from_lane)
        name = f"sc_cross{self.sent}"
        sim.add_vehicle(name, (foe.from_edge, foe.to_edge, *_onwards(net, foe.to_edge)), lane_index=lane.index,
                        pos=max(lane.length - 50.0, 1.0), speed=0.8 * lane.speed, vtype=SCENARIO_TYPE)
        sim.set_speed(name, 0.8 * lane.speed)
        self.sent += 1
        self.next_at = sim.time + float(self.headways_s[self.sent - 1])
        self.log(sim, f"{name} inserted")


def _onwards(net: RoadNetwork, edge: str, min_m: float = 150.0) -> tuple[str, ...]:
    """Edges after ``edge`` (the first successor each time) for at least ``min_m`` [m] or to a dead end."""
    out, total = [], 0.0
    while total < min_m:
        nxt = net.successors(edge)
        if not nxt or nxt[0] in out:
            break
        edge = nxt[0]
        out.append(edge)
        total += net.edge_length[edge]
    return tuple(out)


class RedLightRunner(Script):
    """At a light where the ego goes straight, once its light is green and the ego, at its speed, would reach
    where a perpendicular approach's straight link crosses its own as soon as a car from 70 m before that
    approach's (red) stop line at 1.3 times its lane's limit, such a car comes: it ignores its red and the
    right of way (SUMO keeps its car following) and is given back to SUMO's driver past the junction. A
    lawful driver sees it come, well over its limit, at its red (the privileged scene's ``foe_speeding``)."""

    RUNNER = "sc_runner"
    hazard_kind = "red_light"
    SPEED_FACTOR = 1.3
    FROM_M = 70.0

    def __init__(self, episode, net, rng):
        super().__init__(episode, net, rng)
        self.hazard = junction_hazard(net, episode, self.hazard_kind)
        self.phase = "wait"

    def tick(self, sim, ego):
        from hbmp_bench.sim.sumo import SCENARIO_TYPE

        if ego is None or self.hazard is None or self.phase in ("gone", "missed"):
            return
        net, link, conflict = self.net, self.hazard.link, self.hazard.conflict
        foe = conflict.foe
        if self.phase == "wait":
            to_line = _to_junction_m(net, self.episode, self.hazard, ego)
            if to_line < 0.0:
                self.phase = "missed"
                self.log(sim, "the ego passed the junction first")
                return
            if sim.light_state(link.tls, link.link_index) not in "gG":
                return
            eta = (to_line + conflict.at_m) / max(ego.speed, 1.0)
            lane = net.lane(foe.from_lane)
            speed = self.SPEED_FACTOR * lane.speed
            from_m = min(self.FROM_M, lane.length - 5.0)
            if eta > (from_m + conflict.foe_at_m) / speed:
                return
            from_m = max(min(from_m, speed * eta - conflict.foe_at_m), 15.0)
            sim.add_vehicle(self.RUNNER, (foe.from_edge, foe.to_edge, *_onwards(net, foe.to_edge)),
                            lane_index=lane.index, pos=lane.length - from_m, speed=speed, vtype=SCENARIO_TYPE)
            sim.run_red_lights(self.RUNNER)
            sim.track_lane(self.RUNNER)
            sim.set_speed(self.RUNNER, speed)
            self.phase = "running"
            self.log(sim, f"runs its {sim.light_state(foe.tls, foe.link_index)!r} light from {from_m:.0f} m at "
                          f"{speed:.1f} m/s; the ego {to_line:.1f} m from its green at {ego.speed:.1f} m/s")
        elif self.phase == "running":
            runner = sim.vehicle_state(self.RUNNER)
            if runner is not None and not runner.lane.startswith(":") and net.lane(runner.lane).edge != foe.from_edge:
                sim.give_back(self.RUNNER)
                self.phase = "gone"
                self.log(sim, "past the junction")


class UnprotectedLeft(CrossTraffic):
    """The ego turns left at a light while 6-10 oncoming cars go straight through on their green, 1.5-4 s
    apart: it must wait for a gap."""

    hazard_kind = "unprotected_left"


class Merge(CrossTraffic):
    """The ego's road merges, without a light, into a road on which 8-12 cars arrive 1.5-3 s apart: it
    must find its gap (a motorway on-ramp where the town has one)."""

    hazard_kind = "merge"
    count_range = (8, 12)
    headway_range = (1.5, 3.0)


class GiveWay(CrossTraffic):
    """The ego's road yields at an unsignalised junction to a priority road on which 6-10 cars cross,
    1.5-4 s apart: it must give way."""

    hazard_kind = "give_way"


# ------------------------------------------------------------------ registry
@dataclass(frozen=True)
class ScenarioType:
    """A hazard: its task name, the ability it tests, how its routes are drawn and what it needs.

    Attributes:
        name: task name in episodes and records.
        ability: the group of the ability table (Bench2Drive-like).
        pose_task: the task category whose routes it is drawn from (``Straight`` ...).
        fits: whether an episode's route and town can host it.
        script: the :class:`Script` class that sets it up.
        description: one sentence.
        route_legs: shortest routes chained into one (``suites.sample_chained_episode``); 1: one.
        density: the background traffic of its episodes (``suites.DENSITIES``), None: the suite's.
        max_episodes: at most this many episodes per town (None: the suite's ``episodes_per_task``): a
            type whose episodes are long (several km) costs as much with fewer.
        min_length_factor: its routes are at least this times the town's mean Navigation route long.
    """

    name: str
    ability: str
    pose_task: str
    fits: Callable[[RoadNetwork, Episode], bool]
    script: type[Script]
    description: str
    route_legs: int = 1
    density: str | None = None
    max_episodes: int | None = None
    min_length_factor: float = 0.0


SCENARIO_TYPES: dict[str, ScenarioType] = {}


def register_scenario_type(kind: ScenarioType) -> ScenarioType:
    """Add a scenario type: a task name of its own (labelled by its name in reports)."""
    if kind.name in SCENARIO_TYPES or kind.name in TASKS:
        raise ValueError(f"scenario type {kind.name!r} is already registered")
    SCENARIO_TYPES[kind.name] = kind
    TASK_LABELS.setdefault(kind.name, kind.name)
    return kind


def all_tasks() -> tuple[str, ...]:
    """Every task name in report order: the CoRL2017 task categories, then the scenario types."""
    return (*TASKS, *SCENARIO_TYPES)


def _hosts_hazard(script: type[Script]) -> Callable[[RoadNetwork, Episode], bool]:
    """``fits`` of a junction hazard's type: its route has a junction of the script's ``hazard_kind``."""
    return lambda net, ep: junction_hazard(net, ep, script.hazard_kind) is not None


register_scenario_type(ScenarioType(
    "HardBrake", "Emergency brake", "Straight",
    lambda net, ep: _remaining_m(net, ep) >= HardBrake.AHEAD_M + 30.0,
    HardBrake, "A leader ahead on the ego's lane brakes to a stop at 8 m/s^2, a car's hardest."))
register_scenario_type(ScenarioType(
    "CutIn", "Merging", "Straight",
    lambda net, ep: _remaining_m(net, ep) >= 100.0 and _cut_in_side(net, ep) != 0,
    CutIn, "A faster car overtakes in the next lane, cuts in 2.5-5 m ahead and brakes."))
register_scenario_type(ScenarioType(
    "PedestrianStepsOut", "Pedestrians", "Straight",
    lambda net, ep: _remaining_m(net, ep) >= PedestrianStepsOut.AHEAD_M + 20.0 and bool(net.walkable_edges),
    PedestrianStepsOut, "A pedestrian steps off the kerb ahead and walks across the road."))


register_scenario_type(ScenarioType(
    "UnprotectedLeft", "Intersections", "OneTurn",
    _hosts_hazard(UnprotectedLeft),
    UnprotectedLeft, "A left turn at a light across a stream of oncoming cars."))
register_scenario_type(ScenarioType(
    "GiveWay", "Give way", "Navigation",
    _hosts_hazard(GiveWay),
    GiveWay, "An unsignalised junction where the ego yields to cars crossing on the priority road."))


register_scenario_type(ScenarioType(
    "RedLightRunner", "Traffic signs", "Straight",
    _hosts_hazard(RedLightRunner),
    RedLightRunner, "A car runs its red across the ego's green, well over its speed limit."))
register_scenario_type(ScenarioType(
    "Merge", "Merging", "Navigation",
    _hosts_hazard(Merge),
    Merge, "A merge without a light into a road with a dense stream of cars (an on-ramp in Town04)."))
register_scenario_type(ScenarioType(
    "LongRoute", "Navigation", "Navigation",
    lambda net, ep: ep.turns >= 3,
    Script, "A route of several shortest routes chained (twice a Navigation route or more, 3+ turns) in "
    "regular traffic.", route_legs=4, density="regular", max_episodes=2, min_length_factor=2.0))


def check_scenario_type(name: str) -> ScenarioType:
    from hbmp_bench.errors import UnknownNameError

    try:
        return SCENARIO_TYPES[name]
    except KeyError:
        raise UnknownNameError("scenario type", name, SCENARIO_TYPES) from None


def script_for(episode: Episode, net: RoadNetwork, entropy: list[int]) -> Script | None:
    """The script of an episode whose task is a scenario type (its random stream from the episode's
    entropy), None for the other tasks."""
    kind = SCENARIO_TYPES.get(episode.task)
    if kind is None:
        return None
    return kind.script(episode, net, np.random.default_rng([*entropy, 0x5C]))


def scenario_episode(draw: Callable[[np.random.Generator], Episode], kind: ScenarioType, net: RoadNetwork,
                     rng: np.random.Generator, attempts: int = 200) -> Episode:
    """The first episode ``draw`` gives with ``rng`` whose route fits ``kind``, with the task renamed (a draw
    that raises ValueError, a route it could not make, is one more attempt)."""
    for _ in range(attempts):
        try:
            episode = draw(rng)
        except ValueError:
            continue
        if kind.fits(net, episode):
            return dataclasses.replace(episode, task=kind.name)
    raise ValueError(f"no route of {kind.pose_task} fits {kind.name} in {attempts} draws")
