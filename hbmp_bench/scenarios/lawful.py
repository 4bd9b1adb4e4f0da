"""How long a lawful driver takes for an episode's route, through the town's real signal programs.

The check behind "a lawful driver meets the timeout": a model driver drives the episode's route
(the lanes and junction lanes of ``RoadNetwork.route_path``, the links ``RoadNetwork.route_link``
picks) from a standstill at the episode start, at a steady ``fraction`` of each lane's speed limit,
and stops at every signal whose link may not go (red, yellow, red-yellow) when it reaches the stop
line at that pace, waiting until the link may go. Every episode starts with a fresh simulation, so
every light is at the start of its program when the ego sets off: the arrival times, and the waits,
are those of the real episode for that driver (:meth:`hbmp_bench.maps.signals.Program.wait`).

Time lost to a stop: the wait itself (the deceleration before the line is hidden in it) plus the
re-acceleration, ``v / (2 accel)`` [s] for cruise speed ``v`` [m/s]; the start from a standstill
loses the same. A yellow always stops the model driver (conservative: a lawful driver may go on a
yellow it cannot stop for). Lanes inside junctions have their own (turn) speed limits.

Why not the worst case, a full red at every signal: at 0.8 of the limit, the CoRL2017 timeouts of
the small towns leave less time per signal than the clearance intervals alone (Town02: 10.2 s per
signal on corl2017 Navigation episode 7, 6 signals in 255 m, timeout 101.9 s, while yellows and
all-reds take 10.8 s of every red; Town01: 17.2 s). Nor does a departure at any moment of the cycle
fit Town02 (a red at the first light, then the lights of a zig-zag route out of step). What bounds
a route's red time is that its lights start together with the episode: a driver released by one
light meets the next ones at a known point of their cycle.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

from hbmp_bench.maps import net_path
from hbmp_bench.maps.roadnet import Connection, RoadNetwork, RoutePath
from hbmp_bench.maps.signals import Program, read_programs
from hbmp_bench.scenarios.spec import Episode
from hbmp_bench.scenarios.suites import road_network

__all__ = ["LAWFUL_ACCEL", "RouteSignal", "lawful_travel_time", "route_signals"]

LAWFUL_ACCEL = 2.6
"""Acceleration of the model driver [m/s²] (the ego vehicle type's)."""


@dataclass(frozen=True)
class RouteSignal:
    """A signal on a route: the link the route takes and where its stop line is.

    Attributes:
        link: the lane-level link through the junction (its ``tls`` and ``link_index``).
        at_m: distance from the start of the route's first lane to the stop line [m].
        speed: speed limit of the lane before the stop line [m/s].
    """

    link: Connection
    at_m: float
    speed: float


@functools.lru_cache(maxsize=None)
def _programs(town: str) -> dict[str, Program]:
    return read_programs(net_path(town))


def _route_links(net: RoadNetwork, episode: Episode, lanes: tuple[str, ...]) -> list[Connection]:
    """The link taken between each pair of route edges: from the path's lane on the first edge onto
    its first junction lane (or the next edge's lane)."""
    links, k = [], 0
    for i, lane in enumerate(lanes[:-1]):
        if lane not in net.lanes or net.lanes[lane].edge != episode.route[k]:
            continue
        if k + 1 == len(episode.route):
            break
        step = lanes[i + 1]
        candidates = [c for c in net.links(episode.route[k], episode.route[k + 1]) if c.from_lane == lane]
        link = next((c for c in candidates if (c.via or c.to_lane) == step), None)
        if link is None:
            raise ValueError(f"{episode.key}: no link from {lane} onto {step}")
        links.append(link)
        k += 1
    return links


def _signals(net: RoadNetwork, episode: Episode, path: RoutePath) -> tuple[RouteSignal, ...]:
    links = _route_links(net, episode, path.lanes)
    return tuple(RouteSignal(link, float(path.edge_end[k]), net.lane(link.from_lane).speed)
                 for k, link in enumerate(links) if link.tls)


def _path(net: RoadNetwork, episode: Episode) -> RoutePath:
    return net.route_path(episode.route, episode.start_lane, episode.goal_lane, episode.goal_pos)


def route_signals(episode: Episode) -> tuple[RouteSignal, ...]:
    """The signalised links of the episode's route, in driving order."""
    net = road_network(episode.town)
    return _signals(net, episode, _path(net, episode))


def lawful_travel_time(episode: Episode, fraction: float, accel: float = LAWFUL_ACCEL,
                       depart_s: float = 0.0) -> float:
    """Time [s] from the episode start until the model driver reaches the goal (module docstring),
    cruising at ``fraction`` (0 < fraction <= 1) of each lane's speed limit, accelerating at
    ``accel`` [m/s²] and setting off ``depart_s`` [s] after the episode start."""
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction must be in (0, 1], got {fraction!r}")
    if not accel > 0.0:
        raise ValueError(f"accel must be > 0 [m/s²], got {accel!r}")
    net = road_network(episode.town)
    programs = _programs(episode.town)
    path = _path(net, episode)
    start = path.position(0, episode.start_pos)
    goal = path.position(len(episode.route) - 1, episode.goal_pos)
    speeds = [fraction * net.lane(lane).speed for lane in path.lanes]

    def drive(a: float, b: float) -> float:
        t = 0.0
        for k, v in enumerate(speeds):
            lo, hi = max(a, float(path.offsets[k])), min(b, float(path.offsets[k + 1]))
            if hi > lo:
                t += (hi - lo) / v
        return t

    start_lane = next(k for k in range(len(path.lanes)) if path.offsets[k + 1] > start)
    t = depart_s + speeds[start_lane] / (2.0 * accel)
    at = start
    for signal in _signals(net, episode, path):
        t += drive(at, signal.at_m)
        at = signal.at_m
        wait = programs[signal.link.tls].wait(signal.link.link_index, t)
        if wait > 0.0:
            t += wait + fraction * signal.speed / (2.0 * accel)
    return t + drive(at, goal)
