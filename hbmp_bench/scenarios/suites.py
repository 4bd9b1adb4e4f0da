"""Suites (corl2017, hbmp, nocrash-*, and hbmp-val for choosing checkpoints) and the deterministic episode lists they expand to.

Episodes are a pure function of (suite, town, task) and the town's net: the suite seed drives a
numpy generator that picks start and goal poses among the routes of the town's lane graph whose
task category (turn count) and length fit the task. Starts and goals lie only on driving lanes
(the lane graph has no other) of edges longer than the success radius with a usable speed limit
(:data:`MIN_ROUTE_SPEED_MPS`), in lanes the route can be driven from and to under the env's lane-change
rule (``RoadNetwork.route_drivable``). Nothing here starts SUMO.

Task parameters of a map (route lengths, traffic counts) are its *basis* town's: a built-in town's
own, an imported map's ``like`` town (``maps import --like Town02``), or for an imported map
without one, Town01's scaled by the map's directed road length (as the built-in towns without a
CoRL2017 figure are).
"""

from __future__ import annotations

import dataclasses
import functools
import re
import zlib
from typing import TYPE_CHECKING

import numpy as np

from hbmp_bench.errors import UnknownNameError
from hbmp_bench.maps import TOWNS, available_maps, map_hash, map_info, net_path
from hbmp_bench.scenarios.scenario_types import SCENARIO_TYPES, ScenarioType, scenario_episode
from hbmp_bench.scenarios.spec import TASKS, Episode, Suite, Traffic

if TYPE_CHECKING:
    from hbmp_bench.maps.roadnet import RoadNetwork

MEAN_ROUTE_LENGTH_M: dict[str, tuple[float, float, float]] = {
    "Town01": (200.0, 400.0, 770.0),
    "Town02": (100.0, 170.0, 360.0),
    "Town03": (200.0, 400.0, 770.0),
    "Town04": (300.0, 600.0, 1200.0),
    "Town05": (250.0, 500.0, 900.0),
}
"""Target mean route length [m] for (Straight, One turn, Navigation) per town. Town01/02 are the
CoRL2017 paper's figures; the others scale with town size. Imported maps: their ``like`` town's, else
Town01's scaled by road length (:func:`mean_route_lengths`)."""

MIN_ROUTE_SPEED_MPS = 20.0 / 3.6
"""Starts and goals lie only on edges whose every lane allows at least this speed [m/s] (20 km/h):
no parking aisle or service ramp at a walking pace."""

LENGTH_BAND = (0.5, 1.5)
"""Accepted route length as a fraction of the task's mean length."""

DENSITIES: dict[str, dict[str, tuple[int, int]]] = {
    "empty": {"Town01": (0, 0), "Town02": (0, 0)},
    "corl": {"Town01": (20, 50), "Town02": (15, 50)},
    "regular": {"Town01": (20, 50), "Town02": (15, 50)},
    "dense": {"Town01": (100, 250), "Town02": (70, 150)},
}
"""(vehicles, pedestrians) per density: CoRL2017 / NoCrash counts for Town01 and Town02; other
towns scale Town01's counts by directed road length. A map without walkable edges gets no
pedestrians (none could be spawned)."""


SUITES: dict[str, Suite] = {}


def register_suite(suite: Suite) -> Suite:
    """Add a suite to the registry (names are unique; its tasks are task categories or scenario types)."""
    if suite.name in SUITES:
        raise ValueError(f"suite {suite.name!r} is already registered")
    unknown = [t for t in suite.tasks if t not in TASKS and t not in SCENARIO_TYPES]
    if unknown:
        raise UnknownNameError("task", unknown[0], (*TASKS, *SCENARIO_TYPES))
    SUITES[suite.name] = suite
    return suite


register_suite(
    Suite(
        name="corl2017",
        towns=TOWNS,
        tasks=TASKS,
        episodes_per_task=25,
        seed=2017,
        timeout_waits_at_lights=True,
        description="CARLA CoRL2017 rules: 25 episodes per task and town, timeout at 10 km/h + 10 s and a full "
        "red at every light on the route (CoRL2017's drivers did not stop at lights; these must), success within "
        "2 m, infractions counted but do not end the episode.",
    )
)
register_suite(
    Suite(
        name="hbmp",
        towns=TOWNS,
        tasks=TASKS,
        episodes_per_task=40,
        seed=2020,
        end_on_violation=True,
        timeout_speed_kmh=5.0,
        timeout_extra_s=20.0,
        description="The HBMP paper's protocol: 40 episodes per task, the episode ends at the goal or "
        "at the first rule violation (a red light included); timeout at 5 km/h + 20 s, NoCrash's rule for "
        "drivers that stop at red lights (the paper gives none).",
    )
)
register_suite(
    Suite(
        name="hbmp-val",
        towns=("Town03",),
        tasks=("Navigation", "NavigationDynamic"),
        episodes_per_task=50,
        seed=3,
        end_on_violation=True,
        timeout_speed_kmh=5.0,
        timeout_extra_s=20.0,
        description="Validation, not a test: 50 Navigation and 50 Navigation dynamic episodes of the training "
        "town Town03 under the hbmp suite's rules, drawn from their own seed, on which PPO runs choose among "
        "their checkpoints (train --validate-every, on the first 20 per task unless --validate-episodes says "
        "more); report results on hbmp, corl2017 or nocrash-*.",
    )
)
for _density in ("empty", "regular", "dense"):
    register_suite(
        Suite(
            name=f"nocrash-{_density}",
            towns=TOWNS,
            tasks=("Navigation",),
            episodes_per_task=25,
            seed=2019,
            timeout_speed_kmh=5.0,
            timeout_extra_s=20.0,
            end_on_collision=True,
            density=_density,
            description=f"NoCrash ({_density} traffic): navigation, a collision is a failure, timeout "
            "at 5 km/h + 20 s, red lights reported.",
        )
    )


for _name, _seed_of, _ends, _what in (
        ("scenarios", 2026, True, "The paper's protocol: the episode ends at the goal or the first violation."),
        ("scenarios-lb", 2026, False, "The Leaderboard's protocol: infractions are penalties of the driving "
         "score, not ends."),
        ("scenarios-heldout", 2027, True, "A held-out draw of the same types (its own seed) under the paper's "
         "protocol: whether a ranking on scenarios holds.")):
    register_suite(
        Suite(
            name=_name,
            towns=TOWNS,
            tasks=tuple(SCENARIO_TYPES),
            episodes_per_task=5,
            seed=_seed_of,
            end_on_violation=_ends,
            timeout_speed_kmh=5.0,
            timeout_extra_s=20.0,
            density="empty",
            description="Scenario types (a leader that brakes hard, a cut-in, a pedestrian stepping out ...: "
            "scenarios.scenario_types), 5 episodes per type in every town it fits (2 of the long routes), set up by scripted SUMO "
            f"actors on empty roads; timeout at 5 km/h + 20 s. {_what}",
        )
    )


register_suite(
    Suite(
        name="multi",
        towns=TOWNS,
        tasks=("NavigationDynamic",),
        episodes_per_task=5,
        seed=2044,
        end_on_violation=True,
        timeout_speed_kmh=5.0,
        timeout_extra_s=20.0,
        density="regular",
        agents=8,
        description="Multi-agent: 8 goal-directed vehicles per episode, each with its own start, goal and "
        "Navigation route, all driven by the evaluated policy among SUMO's traffic (CoRL2017's regular counts) and "
        "pedestrians; every vehicle's episode ends by the hbmp suite's rules (its goal or its first violation; "
        "timeout at 5 km/h + 20 s of its own route) and is scored on its own record; the scene runs until every "
        "vehicle's has ended.",
    )
)

AGENT_START_SPACING_M = 15.0
"""Least distance between two goal-directed vehicles' starts on the same lane [m] (all stand at the start)."""
AGENTS_STREAM = 0x4147454E54
"""Entropy word of the draw of a multi-agent episode's other vehicles (apart from the episode's own draw)."""


def with_agents(episode: Episode, agents: int, suite: Suite) -> Episode:
    """``episode`` with ``agents - 1`` other goal-directed vehicles (``Episode.others``), drawn as the
    episode's own pose task draws (:func:`sample_episode`) from a generator of (episode seed,
    :data:`AGENTS_STREAM`, k): a pure function of the episode. A start within
    :data:`AGENT_START_SPACING_M` of another vehicle's on the same lane is drawn again. ``agents=1``:
    the episode without others."""
    if agents < 1:
        raise ValueError(f"agents must be >= 1, got {agents}")
    if agents == 1:
        return dataclasses.replace(episode, others=())
    pose_task = "Navigation" if episode.task == "NavigationDynamic" else episode.task
    if pose_task not in TASKS:
        raise ValueError(f"{episode.task} is a scenario type: its episodes have one goal-directed vehicle")
    starts = [(episode.start_lane, episode.start_pos)]
    others = []
    for k in range(1, agents):
        rng = np.random.default_rng([episode.seed, AGENTS_STREAM, k])
        for _ in range(100):
            other = sample_episode(episode.town, pose_task, rng, suite=suite, index=episode.index, seed=episode.seed,
                                   traffic=episode.traffic)
            if all(lane != other.start_lane or abs(pos - other.start_pos) >= AGENT_START_SPACING_M
                   for lane, pos in starts):
                break
        else:
            raise ValueError(f"no free start for vehicle {k} of {episode.key} in {episode.town}")
        starts.append((other.start_lane, other.start_pos))
        others.append(dataclasses.replace(other, task=episode.task))
    return dataclasses.replace(episode, others=tuple(others))


def get_suite(name: str | Suite) -> Suite:
    """A registered suite by name (or the suite itself)."""
    if isinstance(name, Suite):
        return name
    try:
        return SUITES[name]
    except KeyError:
        raise UnknownNameError("suite", name, SUITES) from None


def check_town(town: str) -> str:
    """Return ``town`` if it names a built-in or imported map, else raise naming the valid ones."""
    valid = available_maps()
    if town not in valid:
        raise UnknownNameError("town", town, valid)
    return town


def check_task(task: str) -> str:
    """Return ``task`` if it is a task category or a scenario type, else raise naming the valid ones."""
    if task not in TASKS and task not in SCENARIO_TYPES:
        raise UnknownNameError("task", task, (*TASKS, *SCENARIO_TYPES))
    return task


def road_network(town: str) -> RoadNetwork:
    """The lane graph of a town (cached per process; sumolib loads on the first call)."""
    from hbmp_bench.maps.roadnet import load_road_network

    return load_road_network(str(net_path(check_town(town))))


def basis_town(town: str) -> str:
    """The town whose task parameters ``town`` takes: itself if built-in, else the ``like`` town it
    was imported with, else itself (parameters scaled from Town01 by its size)."""
    if town in TOWNS:
        return town
    return map_info(check_town(town)).get("like") or town


def traffic_for(town: str, task: str, density: str | None) -> Traffic:
    """Background traffic of a (town, task) under a density (None: the task's CoRL default): the
    counts of the town's :func:`basis_town`, no pedestrians where the town has no walkable edge."""
    if density is None:
        density = "corl" if task == "NavigationDynamic" else "empty"
    if density not in DENSITIES:
        raise UnknownNameError("density", density, DENSITIES)
    table = DENSITIES[density]
    basis = basis_town(town)
    if basis in table:
        vehicles, pedestrians = table[basis]
    else:
        scale = _road_length(basis) / _road_length("Town01")
        vehicles, pedestrians = (round(n * scale) for n in table["Town01"])
    if not road_network(town).walkable_edges:
        pedestrians = 0
    return Traffic(vehicles, pedestrians)


def mean_route_lengths(town: str) -> tuple[float, float, float]:
    """Target mean route length [m] of (Straight, One turn, Navigation) in ``town``: its
    :func:`basis_town`'s from :data:`MEAN_ROUTE_LENGTH_M`, else Town01's scaled by road length."""
    basis = basis_town(town)
    if basis in MEAN_ROUTE_LENGTH_M:
        return MEAN_ROUTE_LENGTH_M[basis]
    scale = _road_length(basis) / _road_length("Town01")
    return tuple(round(m * scale, 1) for m in MEAN_ROUTE_LENGTH_M["Town01"])


def _road_length(town: str) -> float:
    return _road_length_of(town, map_hash(town))


@functools.lru_cache(maxsize=None)
def _road_length_of(town: str, net_hash: str) -> float:
    return float(sum(road_network(town).edge_length.values()))


def episode_edges(town: str, success_radius_m: float) -> frozenset[str]:
    """Edges a start or goal may lie on: longer than ``success_radius_m`` [m], every lane at least
    :data:`MIN_ROUTE_SPEED_MPS`."""
    net = road_network(town)
    return frozenset(e for e, lanes in net.edge_lanes.items()
                     if net.edge_length[e] > success_radius_m
                     and min(net.lanes[ln].speed for ln in lanes) >= MIN_ROUTE_SPEED_MPS)


def _route_table(town: str) -> tuple[tuple[str, str, int, tuple[str, ...]], ...]:
    return _route_table_of(town, map_hash(town))


@functools.lru_cache(maxsize=None)
def _route_table_of(town: str, net_hash: str) -> tuple[tuple[str, str, int, tuple[str, ...]], ...]:
    """Every (start edge, goal edge, turns, route) of a town, sorted (``net_hash``: its net, so that
    a map imported again under the same name is read again)."""
    net = road_network(town)
    rows = []
    for source in net.drivable_edges:
        dist, prev = net.shortest_tree(source)
        for target in sorted(dist):
            if target == source:
                continue
            route = net.path_to(prev, source, target)
            rows.append((source, target, net.count_turns(route), route))
    return tuple(rows)


def _task_filter(task: str, turns: int) -> bool:
    if task == "Straight":
        return turns == 0
    if task == "OneTurn":
        return turns == 1
    return True


def _mean_length(town: str, task: str) -> float:
    return mean_route_lengths(town)[min(TASKS.index(task), 2)]


def route_reds(town: str, route: tuple[str, ...]) -> tuple[float, ...]:
    """The longest red [s] of each light the route passes, in route order: per signalised junction
    crossing (edge to next edge), the longest red of the links a car can take there."""
    net = road_network(town)
    programs = _programs(town)
    reds = []
    for a, b in zip(route[:-1], route[1:]):
        waits = [programs[c.tls].longest_red(c.link_index) for c in net.links(a, b) if c.tls in programs]
        if waits:
            reds.append(max(waits))
    return tuple(reds)


def lawful_route_time(town: str, route: tuple[str, ...], length_m: float) -> float:
    """A lower bound [s] of the time a lawful driver needs for ``length_m`` [m] along ``route``: the
    length at the route's speed limits (their length-weighted pace over the route's edges) and one
    full wait at the route's slowest light (the longest red of any of its signalised links)."""
    net = road_network(town)
    edges_m = np.array([net.edge_length[e] for e in route])
    limits = np.array([net.lanes[net.edge_lanes[e][0]].speed for e in route])
    pace = float(np.sum(edges_m / np.maximum(limits, 1e-3)) / max(np.sum(edges_m), 1e-9))
    return length_m * pace + max(route_reds(town, route), default=0.0)


def episode_timeout(suite: Suite, town: str, route: tuple[str, ...], length_m: float) -> float:
    """The suite's timeout [s] of a route of ``length_m`` [m]: the length at ``timeout_speed_kmh`` plus
    ``timeout_extra_s``, and with ``timeout_waits_at_lights`` the longest red of every light on the route
    (:func:`route_reds`), rounded to 0.1 s."""
    waits = sum(route_reds(town, route)) if suite.timeout_waits_at_lights else 0.0
    return round(length_m / (suite.timeout_speed_kmh / 3.6) + suite.timeout_extra_s + waits, 1)


def _programs(town: str):
    return _programs_of(town, map_hash(town))


@functools.lru_cache(maxsize=None)
def _programs_of(town: str, net_hash: str):
    from hbmp_bench.maps.signals import read_programs

    return read_programs(net_path(town))


def _seed(*parts: object) -> int:
    return zlib.crc32("/".join(map(str, parts)).encode())


_SALT = re.compile(r"(?:[0-9a-f]{8}){4,8}")


def check_salt(salt: str) -> str:
    """``salt`` if it is "" (the public episodes) or 16-32 bytes in lowercase hex (a whole number
    of 32-bit words), else ValueError."""
    if salt != "" and not (isinstance(salt, str) and _SALT.fullmatch(salt)):
        raise ValueError("a salt is 32 to 64 lowercase hex digits (a multiple of 8), or '' for the public episodes")
    return salt


def episode_entropy(episode_seed: int, reset_seed: int, salt: str = "") -> list[int]:
    """The entropy of an episode run's random streams (``DrivingWorld.start``: where background
    vehicles and pedestrians start and go, SUMO's seed, the light phases): the episode's own seed
    (:func:`episode_list`), the reset seed and, in a salted evaluation, the salt's 32-bit words.
    The start, goal and route never depend on it; "" leaves the public episodes as they were."""
    raw = bytes.fromhex(check_salt(salt))
    return [int(episode_seed), int(reset_seed), *(int.from_bytes(raw[k:k + 4], "big") for k in range(0, len(raw), 4))]


def sample_episode(
    town: str,
    task: str,
    rng: np.random.Generator,
    *,
    suite: Suite,
    index: int,
    seed: int,
    traffic: Traffic,
) -> Episode:
    """Draw one episode of ``task`` in ``town`` with ``rng``.

    Start and goal positions are drawn on the route's first and last edge, both among
    :func:`episode_edges`; the route is the shortest route between them over the links a car can drive
    (``RoadNetwork.successors``). The start lane is one from which the route can be followed: within the
    lane changes the start edge has room for of its good lanes (``RoadNetwork.reachable_start_lanes``). The goal lies in the rightmost
    lane of its edge that a car can reach from where the route's last link lands, with room for its lane
    changes before the goal (``RoadNetwork.reachable_goal_lanes``). Its length is the length driven along its lanes from the start
    lane to the goal lane, junction lanes included (``RoadNetwork.route_length``). Routes whose length falls
    outside the task's band are rejected, and so are poses the route cannot be driven from
    (``RoadNetwork.route_drivable``: a start lane that no lane change can leave before the junction
    where the route turns off it, as on the short edges of real towns' road splits), and so are routes
    whose timeout a lawful driver cannot meet (:func:`lawful_route_time`: at the speed limits, with one
    full red at the route's slowest light, against the suite's :func:`episode_timeout`: CoRL2017's 10 km/h
    + 10 s without its light waits left a 60 m route 32 s, less than one red of CARLA's Town10HD); the band
    widens step by step if a small map has none. (``route_drivable`` redraws 1-4 Town03 episodes per suite of the
    built-in towns, episode rules 9 and 10; CARLA's Town10HD imported: 43 of 335 before them.)
    """
    net = road_network(town)
    usable = episode_edges(town, suite.success_radius_m)
    rows = [r for r in _route_table(town) if _task_filter(task, r[2]) and r[0] in usable and r[1] in usable]
    if not rows:
        raise ValueError(f"{town} has no route of task {task!r}")
    mean = _mean_length(town, task)
    lo, hi = LENGTH_BAND
    for widen in range(8):
        factor = 1.0 + 0.5 * widen
        for _ in range(200):
            source, target, turns, route = rows[int(rng.integers(len(rows)))]
            start_len, goal_len = net.edge_length[source], net.edge_length[target]
            start_pos = round(float(rng.uniform(0.1, 0.5) * start_len), 2)
            goal_pos = round(float(rng.uniform(0.3, 0.9) * goal_len), 2)
            start_lanes = net.reachable_start_lanes(route, start_pos, goal_pos)
            start_lane = start_lanes[int(rng.integers(len(start_lanes)))]
            goal_lane = net.reachable_goal_lanes(route, goal_pos, start_lane, start_pos)[0]
            length = net.route_length(route, start_pos, goal_pos, start_lane, goal_lane)
            timeout_s = episode_timeout(suite, town, route, length)
            if lo / factor * mean <= length <= hi * factor * mean and \
                    net.route_drivable(route, start_lane, start_pos, goal_lane, goal_pos) and \
                    lawful_route_time(town, route, length) <= timeout_s:
                return Episode(
                    suite=suite.name,
                    town=town,
                    task=task,
                    index=index,
                    seed=seed,
                    start_lane=start_lane,
                    start_pos=start_pos,
                    goal_lane=goal_lane,
                    goal_pos=goal_pos,
                    route=route,
                    route_length_m=round(length, 2),
                    turns=turns,
                    traffic=traffic,
                    timeout_s=timeout_s,
                    success_radius_m=suite.success_radius_m,
                    end_on_violation=suite.end_on_violation,
                    end_on_collision=suite.end_on_collision,
                )
    raise ValueError(f"no {task} route near {mean:.0f} m in {town}")


def sample_chained_episode(town: str, legs: int, rng: np.random.Generator, *, suite: Suite, index: int, seed: int,
                           traffic: Traffic) -> Episode:
    """An episode whose route chains ``legs`` shortest routes (a long route with many junctions): a
    Navigation episode's start and first leg (:func:`sample_episode`), then from each leg's last edge the
    shortest route to a random edge of :func:`episode_edges`, no edge driven twice; the goal on the last
    edge as :func:`sample_episode` places it. ValueError when the chain cannot be made or driven."""
    net = road_network(town)
    first = sample_episode(town, "Navigation", rng, suite=suite, index=index, seed=seed, traffic=traffic)
    route = list(first.route)
    usable = sorted(episode_edges(town, suite.success_radius_m))
    for _ in range(legs - 1):
        dist, prev = net.shortest_tree(route[-1])
        targets = [e for e in usable if e in dist and e not in route]
        if not targets:
            raise ValueError(f"no leg from {route[-1]} in {town}")
        leg = net.path_to(prev, route[-1], targets[int(rng.integers(len(targets)))])
        if set(leg[1:]) & set(route):
            raise ValueError("the chain drives an edge twice")
        route.extend(leg[1:])
    route_t = tuple(route)
    goal_pos = round(float(rng.uniform(0.3, 0.9) * net.edge_length[route_t[-1]]), 2)
    start_lanes = net.reachable_start_lanes(route_t, first.start_pos, goal_pos)
    start_lane = start_lanes[int(rng.integers(len(start_lanes)))]
    goal_lane = net.reachable_goal_lanes(route_t, goal_pos, start_lane, first.start_pos)[0]
    length = net.route_length(route_t, first.start_pos, goal_pos, start_lane, goal_lane)
    timeout_s = episode_timeout(suite, town, route_t, length)
    if not (net.route_drivable(route_t, start_lane, first.start_pos, goal_lane, goal_pos)
            and lawful_route_time(town, route_t, length) <= timeout_s):
        raise ValueError("the chained route cannot be driven in time")
    return dataclasses.replace(first, start_lane=start_lane, goal_lane=goal_lane, goal_pos=goal_pos, route=route_t,
                               route_length_m=round(length, 2), turns=net.count_turns(route_t), timeout_s=timeout_s)


def suite_episodes(suite_name: str, town: str, task: str) -> tuple[Episode, ...]:
    """The deterministic episode list of a suite for one (town, task) (cached per net: see
    :func:`episode_list`)."""
    check_town(town)
    return _cached_episodes(suite_name, town, task, map_hash(town))


@functools.lru_cache(maxsize=None)
def _cached_episodes(suite_name: str, town: str, task: str, net_hash: str) -> tuple[Episode, ...]:
    return episode_list(suite_name, town, task)


def episode_list(suite_name: str, town: str, task: str) -> tuple[Episode, ...]:
    """The deterministic episode list of a suite for one (town, task), drawn afresh.

    Episode i draws from its own generator seeded by (suite seed, town, pose task, i), so the
    list is identical for every agent and machine. Navigation with dynamic obstacles uses the
    same poses as Navigation (as in CoRL2017), with the suite's traffic.
    """
    suite = get_suite(suite_name)
    check_town(town)
    check_task(task)
    kind = SCENARIO_TYPES.get(task)
    if kind is not None:
        return _scenario_episodes(suite, town, kind)
    pose_task = "Navigation" if task == "NavigationDynamic" else task
    traffic = traffic_for(town, task, suite.density)
    episodes = []
    for i in range(suite.episodes_per_task):
        episode = sample_episode(
            town,
            pose_task,
            np.random.default_rng(_seed(suite.seed, town, pose_task, i)),
            suite=suite,
            index=i,
            seed=_seed(suite.seed, town, task, i) % (2**31),
            traffic=traffic,
        )
        episode = dataclasses.replace(episode, task=task)
        episodes.append(with_agents(episode, suite.agents, suite) if suite.agents > 1 else episode)
    return tuple(episodes)


def _scenario_episodes(suite: Suite, town: str, kind: ScenarioType) -> tuple[Episode, ...]:
    """A scenario type's episodes in a town: episode i draws routes of the type's pose task from its own
    generator (suite seed, town, type, i) until one fits the type. The list ends at the first episode none
    of whose draws fits (``scenario_episode``'s attempts): () where the town cannot host the type (a cut-in
    needs two lanes one way), fewer than ``episodes_per_task`` where its places are rare."""
    net = road_network(town)
    traffic = traffic_for(town, kind.pose_task, kind.density or suite.density)
    episodes = []
    for i in range(min(suite.episodes_per_task, kind.max_episodes or suite.episodes_per_task)):
        def draw(rng, i=i):
            seed = _seed(suite.seed, town, kind.name, i) % (2**31)
            if kind.route_legs > 1:
                episode = sample_chained_episode(town, kind.route_legs, rng, suite=suite, index=i, seed=seed,
                                                 traffic=traffic)
            else:
                episode = sample_episode(town, kind.pose_task, rng, suite=suite, index=i, seed=seed, traffic=traffic)
            if episode.route_length_m < kind.min_length_factor * mean_route_lengths(town)[2]:
                raise ValueError("shorter than the type's routes")
            return episode
        try:
            episodes.append(scenario_episode(draw, kind, net, np.random.default_rng(_seed(suite.seed, town, kind.name, i))))
        except ValueError:
            break
    return tuple(episodes)


def held_episodes(suite_name: str, town: str, task: str) -> int:
    """Episodes a suite holds for one (town, task): ``episodes_per_task``, fewer for a scenario type in a town
    that cannot host all of it (``_scenario_episodes``: none where it does not fit)."""
    if task in SCENARIO_TYPES:
        return len(suite_episodes(suite_name, town, task))
    return get_suite(suite_name).episodes_per_task


def selection_size(suite_name: str, towns, tasks, indices) -> int:
    """Episodes a selection of a suite holds: every (town, task, index) but the indices past
    :func:`held_episodes`."""
    return sum(sum(1 for i in indices if i < held_episodes(suite_name, town, task)) for town in towns for task in tasks)


def all_episodes(suite_name: str) -> list[Episode]:
    """Every episode of a suite, ordered by town, task and index."""
    suite = get_suite(suite_name)
    return [ep for town in suite.towns for task in suite.tasks for ep in suite_episodes(suite.name, town, task)]
