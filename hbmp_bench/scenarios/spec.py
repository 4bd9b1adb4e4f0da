"""Frozen scenario specifications: tasks, suites and the episodes they expand to."""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field, replace
from dataclasses import fields as dataclass_fields

TASKS: tuple[str, ...] = ("Straight", "OneTurn", "Navigation", "NavigationDynamic")
"""The CoRL2017 task categories, as used in env ids (``hbmp_bench/Town01-OneTurn-v0``)."""

EPISODE_RULES_VERSION = 11
"""Version of how a suite's episodes are drawn and measured, part of ``Suite.definition_hash`` so
that records and leaderboard results of older episode lists never mix with current ones. Bump it
whenever the episode lists or their route lengths / timeouts change. 2: route length is the length
driven along the route's lanes, junction lanes included (1 left the junction lanes out). 3: routes
are the shortest by that length (2 chose them by edge lengths alone). 4: the lanes behind that length
reach the goal lane in time (``RoadNetwork.route_lanes``: one lane change takes 3 s at the limit).
5: the towns' lights follow the kinematic yellow rule (3.4 s at 50 km/h, 3.8 s at 60 km/h), a 2 s
all-red after every yellow, no protected left phases, and 20 s greens (12 s in Town02 and Town03);
the routes are unchanged, the signals the ego meets are not. 6: Town04's outer ramps bridge 6 m over
the inner carriageway (a car on the bridge no longer collides with one below); those ramps are
0.6 m longer. 7: the goal lane is the rightmost lane of the goal edge that a car entering it by the route's
last link can reach with room for its lane changes before the goal (``RoadNetwork.reachable_goal_lanes``); it
was always the rightmost, which in Town03 and Town05 lay 1-2 lanes from where the only link lands, 10-20 m
before the goal. 8: routes take no junction link sharper than a 3 m radius (``SHARPEST_TURN_RADIUS_M``: Town04's
ramp terminals had 135-degree turns within 13 m, Town03 and Town05 a few 2.5 m ones), and the start lane is one
from which the route can be followed (``RoadNetwork.reachable_start_lanes``: Town03 had starts 6-8 m before a
junction, a lane or two from the only lane that continues, and the ego looped the block until it timed out).
9: poses the route cannot be driven from are drawn again (``RoadNetwork.route_drivable``), a lane change needing
``LANE_CHANGE_BEGIN_M`` (5 m) of an edge before the lane-change cutoff: Town03 routes that needed a change on a
12.5 m edge behind a junction (hbmp Navigation 19 and 23). 10: ``route_drivable`` allows one lane change per
``LANE_CHANGE_BEGIN_M`` of an edge before the cutoff, not any number (two changes on a 16 m Town03 edge after a
roundabout: hbmp Navigation 6 and 32). 11: routes whose timeout a lawful driver cannot meet are drawn again
(``scenarios.suites.lawful_route_time``: the route at its speed limits plus one full red at its slowest light):
two corl2017 Town03 Straight episodes, and 9 of 25 Straight episodes of CARLA's Town10HD imported. The built-in
towns' junction lanes are drawn with 20 points (5) and their crossings are 2 m wide (4): right turns passed into
pedestrians waiting to cross (``RoadNetwork.crossing_clearance``). Rules that only some suites use are suite
fields instead (:data:`FIELDS_SINCE_RULES_11`): corl2017's timeout adds a full red at every light on the route
(``Suite.timeout_waits_at_lights``; its hash changed, the other suites' did not)."""

TASK_LABELS = {
    "Straight": "Straight",
    "OneTurn": "One turn",
    "Navigation": "Navigation",
    "NavigationDynamic": "Nav. dynamic",
}


@dataclass(frozen=True)
class Traffic:
    """Background traffic of an episode: vehicle and pedestrian counts."""

    vehicles: int = 0
    pedestrians: int = 0

    def __post_init__(self):
        if self.vehicles < 0 or self.pedestrians < 0:
            raise ValueError(f"traffic counts must be >= 0, got {self}")


@dataclass(frozen=True)
class Suite:
    """An evaluation protocol: which towns and tasks, how many episodes, the rules.

    Attributes:
        name: registry name (``corl2017``, ``hbmp``, ``nocrash-regular`` ...).
        towns / tasks: what it covers.
        episodes_per_task: episodes per (town, task).
        seed: the suite seed; episode lists are a pure function of it.
        timeout_speed_kmh / timeout_extra_s: timeout = route length at this speed + extra [s].
        success_radius_m: goal reached when the ego centre is this close to the goal [m].
        end_on_violation: end the episode at the first collision, red light, wrong lane or
            off-road (the paper's protocol); CoRL2017 counts infractions and goes on.
        end_on_collision: end at the first collision (NoCrash: a collision is a failure).
        density: background traffic for every task (``empty``, ``regular``, ``dense``);
            ``None`` = CoRL2017 counts on Navigation dynamic, empty roads elsewhere.
        timeout_waits_at_lights: the timeout also allows a full red at every light on the route (the
            longest red of the links the route takes, summed over its signalised junctions), for a timeout
            rule made for drivers that do not stop at red lights (CoRL2017's, in CARLA 0.8, where a red
            light was no failure): without it a lawful driver meets its 10 km/h + 10 s only where the
            lights happen to be green, and the expert timed out in 5 of 25 Town02 Navigation dynamic episodes.
        agents: goal-directed vehicles per episode, the ego included (1: a single-ego suite). With more, every
            episode also holds ``agents - 1`` other goal-directed vehicles (``Episode.others``, drawn from the
            episode's seed by ``scenarios.suites.with_agents``), each driven by the evaluated policy and scored
            on its own record by the same rules.
    """

    name: str
    towns: tuple[str, ...]
    tasks: tuple[str, ...]
    episodes_per_task: int
    seed: int
    timeout_speed_kmh: float = 10.0
    timeout_extra_s: float = 10.0
    success_radius_m: float = 2.0
    end_on_violation: bool = False
    end_on_collision: bool = False
    density: str | None = None
    description: str = ""
    timeout_waits_at_lights: bool = False
    agents: int = 1

    def __post_init__(self):
        if self.agents < 1:
            raise ValueError(f"agents must be >= 1, got {self.agents}")
        if self.episodes_per_task <= 0:
            raise ValueError(f"episodes_per_task must be > 0, got {self.episodes_per_task}")
        if self.timeout_speed_kmh <= 0:
            raise ValueError("timeout_speed_kmh must be > 0")
        if not self.tasks:
            raise ValueError("a suite has at least one task")

    def definition_hash(self) -> str:
        """Short hash of everything that defines the suite's episodes and rules (its fields and
        ``EPISODE_RULES_VERSION``). A field added after rules 11 (:data:`FIELDS_SINCE_RULES_11`) enters it only
        where it differs from its default: a new rule changes the hash of the suites that use it, not of
        those whose episodes it leaves as they were (and whose results stay valid)."""
        defaults = {f.name: f.default for f in dataclass_fields(self)}
        fields = {k: v for k, v in asdict(self).items() if k not in FIELDS_SINCE_RULES_11 or v != defaults[k]}
        if any(t not in TASKS for t in self.tasks):  # scenario types: their scripts are part of the episodes
            fields["scenario_rules"] = SCENARIO_RULES_VERSION
        blob = json.dumps({**fields, "episode_rules": EPISODE_RULES_VERSION}, sort_keys=True, default=list).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


SCENARIO_RULES_VERSION = 2
"""Version of the scenario types' scripts (``scenarios.scenario_types``: when and how their actors act), part
of the definition hash of a suite that holds scenario types, so that results of other scripts never mix. Bump
it whenever a script changes. 2: streams of 6-12 cars at headways drawn per car (1.5-4 s: gaps to judge), a
cut-in 2.5-5 m ahead that then brakes, a runner at 1.3 times its limit, a leader that brakes within 18 m."""

FIELDS_SINCE_RULES_11 = ("timeout_waits_at_lights", "agents")
"""Suite fields added after episode rules 11: at their default they leave the definition hash as it was."""


@dataclass(frozen=True)
class Episode:
    """One fully specified episode: map, route, traffic, rules and seed.

    Positions are along SUMO lanes [m]; ``route`` is the edge sequence from the start edge
    to the goal edge (the shortest route, the paper's A* global route). ``route_length_m`` [m] is
    the length driven from ``start_pos`` on ``start_lane`` to ``goal_pos``, along the route's
    lanes and the junction lanes between them (``RoadNetwork.route_length``); ``timeout_s`` [s]
    and route completion are measured against it.

    ``others``: the other goal-directed vehicles of a multi-agent episode (``Suite.agents``; vehicles
    ``ego1``, ``ego2`` ... in that order), each an Episode of its own start, goal, route and timeout, with
    this one's suite, town, task, index, seed, traffic and rules; () for a single-ego episode.
    """

    suite: str
    town: str
    task: str
    index: int
    seed: int
    start_lane: str
    start_pos: float
    goal_lane: str
    goal_pos: float
    route: tuple[str, ...]
    route_length_m: float
    turns: int
    traffic: Traffic = field(default_factory=Traffic)
    timeout_s: float = 300.0
    success_radius_m: float = 2.0
    end_on_violation: bool = False
    end_on_collision: bool = False
    others: tuple["Episode", ...] = ()

    def __post_init__(self):
        if not self.route:
            raise ValueError("route must not be empty")
        if self.route_length_m <= 0 or self.timeout_s <= 0:
            raise ValueError(f"route length and timeout must be > 0 ({self.route_length_m}, {self.timeout_s})")

    @property
    def key(self) -> str:
        """Unique key of the episode within its suite: ``Town01/Straight/3``."""
        return f"{self.town}/{self.task}/{self.index}"

    @property
    def agents(self) -> tuple["Episode", ...]:
        """Every goal-directed vehicle's episode, the ego's (this one, without ``others``) first."""
        return (replace(self, others=()), *self.others) if self.others else (self,)
