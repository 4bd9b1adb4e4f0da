"""Static view of a SUMO network: drivable lanes, connections, routing and lane geometry.

Read once per net file (cached) with sumolib; never starts a simulation. The scenario
registry routes on it, the observation builders take lane shapes from it and the metric
detectors locate footprints on it, so every room agrees on one lane graph.

Conventions: lane ids and indices are SUMO's (index 0 is the rightmost lane, which is a
sidewalk where the edge has one). A *drivable* lane allows the ``passenger`` class.
Positions are SUMO network coordinates [m].
"""

from __future__ import annotations

import functools
import heapq
import math
import os
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Mapping

import numpy as np

TURN_DIRECTIONS = frozenset("lLrR")
"""SUMO link directions that count as a turn (left, partly left, right, partly right)."""


LANE_CHANGE_CUTOFF_M = 10.0
"""No lane change starts within this distance of a lane's end [m]: the last metres before a
junction (solid lines in real towns); a change begun there would enter the junction on another
lane's connection."""


LANE_CHANGE_BEGIN_M = 5.0
"""Room [m] before ``LANE_CHANGE_CUTOFF_M`` each lane change needs to begin in (``RoadNetwork.route_drivable``):
Town03's 12.5 m edges behind a junction leave a car 2.5 m, its 16 m ones 6 m (one change, not two); routes that
needed more looped the expert round the block until it timed out."""

SHARPEST_TURN_RADIUS_M = 3.0
"""Routes take no junction link that turns tighter than this radius [m] (``sharpest_turn_radius`` of its
centreline). The ego's bicycle model turns no tighter than wheelbase / tan(max_steer) = 4.1 m; cutting
across its lane's width it follows the towns' 3.9 m right turns, not the 1.7-2.7 m ones a junction can
draw (Town04's ramp terminals turned 135 degrees within 13 m: the expert left the road there in 12 of
160 episodes). SUMO's own vehicles still drive every link."""

TURN_WINDOW_M = 3.0
"""Arc length [m] over which ``sharpest_turn_radius`` measures a heading change."""


WALK_SPAWN_MIN_M = 2.0
"""Pedestrians are spawned only on edges longer than this [m] (1 m from either end)."""

WITHIN_REACH_M = 25.0
"""Road [m] between the lane a car was on and the one SUMO reports next, beyond which the report is a jump (onto
another level) and not a move (:meth:`RoadNetwork.within_reach`)."""


@dataclass(frozen=True)
class Connection:
    """One drivable link from a lane of an edge to a lane of the next edge.

    ``via`` is the first internal (junction) lane the link runs over, ``""`` if none;
    ``direction`` is SUMO's link direction (``s`` straight, ``l``/``L`` left, ``r``/``R``
    right, ``t`` turnaround); ``tls``/``link_index`` name the traffic light that controls it;
    ``state`` is SUMO's right of way of a link without a light (``M`` major, ``m`` minor, ``=``
    equal, ``s`` stop, ``w`` all-way stop; ``o`` where a light controls it).
    """

    from_edge: str
    from_lane: str
    to_edge: str
    to_lane: str
    via: str
    direction: str
    tls: str
    link_index: int
    state: str = "M"


@dataclass(frozen=True)
class LinkConflict:
    """Where another link through the same junction comes within a car's width of a link (a
    crossing, a merge, a close pass): from ``at_m`` to ``clear_m`` [m] along this link's junction
    lanes, ``foe_at_m`` to ``foe_clear_m`` [m] along the ``foe`` link's, both from the junction's
    entry (the stop line)."""

    foe: Connection
    at_m: float
    clear_m: float
    foe_at_m: float
    foe_clear_m: float


@dataclass(frozen=True)
class Crossing:
    """A pedestrian crossing over the roads of a junction: its centreline (N, 2) [m] and width [m],
    the walking areas at its two ends, and the traffic light link of its pedestrian signal
    (``tls`` "" where it has none)."""

    id: str
    shape: np.ndarray
    width: float
    walkingareas: tuple[str, ...]
    tls: str
    link_index: int


CONFLICT_WIDTH_M = 2.2
"""Two links conflict where their centrelines come closer than this [m] (two car widths' halves
and a margin)."""


@dataclass(frozen=True)
class Lane:
    """A drivable lane: id, SUMO index, shape (N, 2) [m], length [m], width [m], speed [m/s]."""

    id: str
    edge: str
    index: int
    shape: np.ndarray
    length: float
    width: float
    speed: float

    @functools.cached_property
    def shape_length(self) -> float:
        """Length of the drawn shape [m], what a car in this lane drives. SUMO's ``length`` (the unit
        of lane positions) is shared by all lanes of an edge, so on a curved multi-lane edge it can
        differ from the shape's by a few percent (20% on a roundabout's inner lane)."""
        seg = np.diff(self.shape, axis=0)
        return float(np.hypot(seg[:, 0], seg[:, 1]).sum())


class RoadNetwork:
    """Drivable lane graph of one SUMO net: the tables its readers read (:meth:`from_sumo`), and the
    graph, routes and lane geometry derived from them.

    Build one with ``RoadNetwork.from_sumo(path)`` (or the cached :func:`load_road_network`); the
    constructor takes the tables as they are.

    Args:
        path: the ``.net.xml`` the tables were read from (its name appears in messages).
        lanes: drivable lanes of normal edges by id, in the net's edge order.
        internal_lanes: drivable junction (internal) lanes by id.
        edge_lanes: normal edge -> its drivable lane ids, SUMO index order.
        edge_from_to: normal edge -> (from node, to node).
        connections: normal edge -> every drivable link leaving it (:func:`read_connections`).
        lane_next: lane -> (next lane or junction lane, the normal edge it leads onto) per link.
        junction_shapes: node -> its polygon (N, 2) [m] (nodes with three or more shape points).
        walkable_edges: where pedestrians are spawned (:func:`read_walkable_edges`).
        tls_ids: traffic light ids, sorted.
        crossings: pedestrian crossings by edge id.
    """

    def __init__(self, path: str | Path, *, lanes: dict[str, Lane], internal_lanes: dict[str, Lane],
                 edge_lanes: dict[str, tuple[str, ...]], edge_from_to: dict[str, tuple[str, str]],
                 connections: dict[str, tuple[Connection, ...]], lane_next: dict[str, tuple[tuple[str, str], ...]],
                 junction_shapes: dict[str, np.ndarray], walkable_edges: tuple[str, ...], tls_ids: tuple[str, ...],
                 crossings: dict[str, Crossing]):
        self.path = Path(path)
        self._trees: dict[str, tuple[Mapping[str, float], Mapping[str, str]]] = {}
        self.lanes = lanes
        self.edge_lanes = edge_lanes
        self.internal_lanes = internal_lanes
        self.edge_from_to = edge_from_to
        self.junction_shapes = junction_shapes
        self.walkable_edges = walkable_edges
        """Road edges (with a drivable lane, so in ``edge_length``) beside a walkable lane, longer than
        ``WALK_SPAWN_MIN_M``: where pedestrians are spawned. A footpath of an imported map (no drivable
        lane) or a sliver edge is walked, not spawned on."""
        self.connections = connections
        self._link_end = {c.via: c.to_lane for conns in self.connections.values() for c in conns if c.via}
        """The lane a link leads onto, by the link's first junction lane."""
        self.lane_next = lane_next
        pairs = {v: k for k, v in self.edge_from_to.items()}
        self.opposite: dict[str, str | None] = {
            e: pairs.get((t, f)) for e, (f, t) in self.edge_from_to.items()
        }
        self.edge_length = {e: self.lanes[ids[0]].length for e, ids in self.edge_lanes.items()}
        self.drivable_edges: tuple[str, ...] = tuple(sorted(self.edge_lanes))
        self.tls_ids = tls_ids
        self.crossings = crossings
        """Pedestrian crossings by edge id."""

    @classmethod
    def from_sumo(cls, net_path: str | Path) -> RoadNetwork:
        """Read a SUMO ``.net.xml`` with sumolib (junction lanes included, pedestrian links not) through the
        small readers of this module."""
        import sumolib

        path = Path(net_path)
        net = sumolib.net.readNet(str(path), withInternal=True, withPedestrianConnections=False)
        lanes, internal_lanes, edge_lanes, edge_from_to = read_lanes(net)
        return cls(path, lanes=lanes, internal_lanes=internal_lanes, edge_lanes=edge_lanes, edge_from_to=edge_from_to,
                   connections=read_connections(net, lanes, edge_lanes),
                   lane_next=read_lane_next(net, lanes, internal_lanes), junction_shapes=read_junction_shapes(net),
                   walkable_edges=read_walkable_edges(net),
                   tls_ids=tuple(sorted(t.getID() for t in net.getTrafficLights())),
                   crossings=read_crossings(net, path))

    # ---------------------------------------------------------------- graph
    # ``connections`` holds every link of the net (foes, stop lines); routes and the lanes a car
    # follows use the links it can drive: ``successors`` and ``links``.
    @functools.cached_property
    def _drivable_links(self) -> dict[str, tuple[Connection, ...]]:
        return {edge: tuple(c for c in conns if self.link_turn_radius(c) >= SHARPEST_TURN_RADIUS_M)
                for edge, conns in self.connections.items()}

    def link_turn_radius(self, link: Connection) -> float:
        """Tightest radius [m] of a link's junction lanes (``sharpest_turn_radius``; inf without any)."""
        shape = self.link_shape(link)
        return sharpest_turn_radius(shape) if len(shape) >= 2 else float("inf")

    def successors(self, edge: str) -> tuple[str, ...]:
        """Edges a car can reach from ``edge`` through one junction (no duplicates, sorted): by a link no
        sharper than ``SHARPEST_TURN_RADIUS_M``."""
        return tuple(sorted({c.to_edge for c in self._drivable_links[edge]}))

    def within_reach(self, from_lane: str, to_lane: str, road_m: float = WITHIN_REACH_M) -> bool:
        """Whether a car on ``from_lane`` can be on ``to_lane`` a moment later: a lane of the same edge, or of
        an edge reached by links (drivable or not) over at most ``road_m`` [m] of the edges between. SUMO maps a
        pushed pose onto the nearest lane of the vehicle's route in 2D, so where the route passes under a
        road it drives over later (Town04's ramps: 772 and 1095 m of road between the two levels) a pose can
        land on the other level: such a jump is not within reach. Real towns split roads into pieces of
        0.1-0.2 m that a car passes between two reports of its lane (CARLA's Town07: 5#1, 5#0 (0.2 m), 4
        (0.2 m), 3), so reach is measured in metres of road, not in junctions."""
        start, goal = self.lanes[from_lane].edge, self.lanes[to_lane].edge
        best, queue = {start: 0.0}, [(0.0, start)]
        while queue:
            dist, edge = heapq.heappop(queue)
            if edge == goal:
                return True
            if dist > best[edge]:
                continue
            through = dist + (self.edge_length.get(edge, 0.0) if edge != start else 0.0)
            if through > road_m:
                continue
            for c in self.connections.get(edge, ()):
                if through < best.get(c.to_edge, math.inf):
                    best[c.to_edge] = through
                    heapq.heappush(queue, (through, c.to_edge))
        return False

    def links(self, edge: str, to_edge: str) -> tuple[Connection, ...]:
        """The lane-level links a car can drive from ``edge`` to ``to_edge`` (no sharper than
        ``SHARPEST_TURN_RADIUS_M``; ``connections`` has them all)."""
        return tuple(c for c in self._drivable_links[edge] if c.to_edge == to_edge)

    def direction(self, edge: str, to_edge: str) -> str:
        """SUMO link direction of the move ``edge`` → ``to_edge`` (first link's)."""
        links = self.links(edge, to_edge)
        if not links:
            raise ValueError(f"no link from {edge!r} to {to_edge!r}")
        return links[0].direction

    def turns(self, route: tuple[str, ...] | list[str]) -> tuple[str, ...]:
        """Link direction at every junction of ``route`` (len(route) - 1 entries)."""
        return tuple(self.direction(a, b) for a, b in zip(route[:-1], route[1:]))

    def count_turns(self, route: tuple[str, ...] | list[str]) -> int:
        """Number of junctions where ``route`` turns left or right."""
        return sum(d in TURN_DIRECTIONS for d in self.turns(route))

    def shortest_tree(self, source: str) -> tuple[Mapping[str, float], Mapping[str, str]]:
        """Dijkstra from the END of ``source`` over the length driven [m]: each step onto an edge
        costs its junction lanes (the shortest link's) plus the edge's length.

        Returns (dist, prev), read-only and computed once per source (an episode's reset draws the
        background routes from them): dist[e] is the length driven from the end of ``source`` to the
        end of ``e``; prev links each reached edge to its predecessor.
        """
        tree = self._trees.get(source)
        if tree is None:
            dist, prev = self._dijkstra(source)
            tree = self._trees[source] = (MappingProxyType(dist), MappingProxyType(prev))
        return tree

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_trees"] = {}  # read-only views do not pickle; a copy computes its own
        return state

    def _dijkstra(self, source: str) -> tuple[dict[str, float], dict[str, str]]:
        dist = {source: 0.0}
        prev: dict[str, str] = {}
        heap = [(0.0, source)]
        while heap:
            d, e = heapq.heappop(heap)
            if d > dist.get(e, np.inf):
                continue
            for nxt in self.successors(e):
                nd = d + self.junction_length(e, nxt) + self.edge_length[nxt]
                if nd < dist.get(nxt, np.inf):
                    dist[nxt] = nd
                    prev[nxt] = e
                    heapq.heappush(heap, (nd, nxt))
        return dist, prev

    def junction_length(self, edge: str, to_edge: str) -> float:
        """Length [m] of the shortest link's junction lanes from ``edge`` onto ``to_edge`` (0 if none)."""
        return self._junction_lengths.get((edge, to_edge), 0.0)

    @functools.cached_property
    def _junction_lengths(self) -> dict[tuple[str, str], float]:
        return {(e, nxt): min(sum(self.lane(ln).shape_length for ln in self.link_lanes(c)) for c in self.links(e, nxt))
                for e in self.edge_length for nxt in self.successors(e) if self.links(e, nxt)}

    @staticmethod
    def path_to(prev: Mapping[str, str], source: str, target: str) -> tuple[str, ...]:
        """Edge sequence from ``source`` to ``target`` read off a ``shortest_tree`` result."""
        path = [target]
        while path[-1] != source:
            path.append(prev[path[-1]])
        return tuple(reversed(path))

    def shortest_route(self, source: str, target: str) -> tuple[str, ...]:
        """Shortest edge route from ``source`` to ``target`` (A* in the paper; Dijkstra here)."""
        if source == target:
            return (source,)
        dist, prev = self.shortest_tree(source)
        if target not in dist:
            raise ValueError(f"no route from {source!r} to {target!r} in {self.path.name}")
        return self.path_to(prev, source, target)

    # ------------------------------------------------------------- lanes
    def lane(self, lane_id: str) -> Lane:
        """A drivable lane (normal or internal) by id."""
        lane = self.lanes.get(lane_id) or self.internal_lanes.get(lane_id)
        if lane is None:
            raise KeyError(lane_id)
        return lane

    def lanes_to(self, edge: str, to_edge: str) -> tuple[str, ...]:
        """Lanes of ``edge`` that have a link onto ``to_edge`` (the lanes that continue a route)."""
        return tuple(sorted({c.from_lane for c in self.links(edge, to_edge)}))

    def route_lanes(self, route: tuple[str, ...], goal_lane: str, goal_pos: float | None = None,
                    change_m: float = 20.0, change_s: float = 3.0,
                    cutoff_m: float = LANE_CHANGE_CUTOFF_M) -> tuple[frozenset[str], ...]:
        """Per edge of ``route``, the lanes a car can leave that edge by and still reach ``goal_lane``
        (on the last edge: the goal lane itself).

        One lane change takes ``max(change_m, change_s * speed limit)`` [m] of an edge's room: its
        length less the last ``cutoff_m`` [m] before the junction where lane changes are closed, or
        on the goal edge the goal's position ``goal_pos`` [m] (None: the goal edge's room like any
        edge's). The good lanes of an edge are those whose link onto the next edge lands within as
        many lane changes of that edge's good lanes as its room allows: before a long edge every
        linking lane; before one without room (a short goal edge, a roundabout's ring segment) only
        a lane whose link lands on a good lane. Where no lane does, the links landing fewest lane
        changes away are kept.
        """
        return self._route_lanes(tuple(route), goal_lane, goal_pos, float(change_m), float(change_s), float(cutoff_m))

    def reachable_start_lanes(self, route: tuple[str, ...], start_pos: float, goal_pos: float,
                              change_m: float = 20.0) -> tuple[str, ...]:
        """Lanes of the route's first edge (rightmost first) from which a car starting at ``start_pos`` [m]
        can follow the route to its goal at ``goal_pos`` [m]: within as many lane changes of the first
        edge's good lanes (:meth:`route_lanes`, to the goal lane of :meth:`reachable_goal_lanes`) as the
        room before ``LANE_CHANGE_CUTOFF_M`` allows, one change taking ``change_m`` [m] (the car starts
        slowly). Every lane for a one-edge route; the good lanes themselves where there is no room."""
        lanes = self.edge_lanes[route[0]]
        if len(route) == 1:
            return lanes
        goal_lane = self.reachable_goal_lanes(route, goal_pos, lanes[0], start_pos)[0]
        good = self.route_lanes(route, goal_lane, goal_pos)[0]
        room = self.edge_length[route[0]] - LANE_CHANGE_CUTOFF_M - start_pos
        return (tuple(lane for lane in lanes if self.changes_into(lane, good) * change_m <= max(room, 0.0))
                or tuple(lane for lane in lanes if lane in good))

    def reachable_goal_lanes(self, route: tuple[str, ...], goal_pos: float, start_lane: str, start_pos: float,
                             change_m: float = 20.0, change_s: float = 3.0) -> tuple[str, ...]:
        """Lanes of the route's last edge (rightmost first) a car can be in at ``goal_pos`` [m]: within as
        many lane changes of a lane the last link lands on (of the start lane, for a one-edge route) as the
        ``goal_pos`` [m] of room allows, one change taking ``max(change_m, change_s * speed limit)`` [m] as
        in :meth:`route_lanes` (from the start, ``change_m``: the car starts slowly)."""
        entries = [start_lane] if len(route) == 1 else [c.to_lane for c in self.links(route[-2], route[-1])]
        return self._goal_lanes(route, entries, goal_pos, start_pos, change_m, change_s) or tuple(entries[:1])

    def _goal_lanes(self, route: tuple[str, ...], entries, goal_pos: float, start_pos: float, change_m: float,
                    change_s: float) -> tuple[str, ...]:
        """Lanes of the route's last edge within reach of a car entering it in one of ``entries`` (see
        :meth:`reachable_goal_lanes`)."""
        goal_edge = route[-1]
        if len(route) == 1:
            room, per_change = goal_pos - start_pos, change_m
        else:
            room, per_change = goal_pos, max(change_m, change_s * self.lanes[self.edge_lanes[goal_edge][0]].speed)
        landings = frozenset(entries)
        return tuple(lane for lane in self.edge_lanes[goal_edge]
                     if self.changes_into(lane, landings) * per_change <= max(room, 0.0))

    def route_drivable(self, route: tuple[str, ...], start_lane: str, start_pos: float, goal_lane: str,
                       goal_pos: float, cutoff_m: float = LANE_CHANGE_CUTOFF_M, change_m: float = 20.0,
                       change_s: float = 3.0, begin_m: float = LANE_CHANGE_BEGIN_M) -> bool:
        """Whether a car in ``start_lane`` at ``start_pos`` [m] can follow ``route`` and be in ``goal_lane`` at
        ``goal_pos`` [m]. Before the last edge it changes lanes only before the action mask closes changes
        (``cutoff_m`` before the junction, ``LANE_CHANGE_CUTOFF_M``), optimistically one change per ``begin_m``
        [m] of the edge ahead of that (``LANE_CHANGE_BEGIN_M``); on the last edge it reaches the goal lane from
        where it enters with the room :meth:`reachable_goal_lanes` gives its changes (how the goal lane was
        chosen).

        False when a lane the car is confined to has no link onto the route's next edge (an edge
        shorter than the cutoff, as real towns have where a road splits, leaves no room to reach a
        turn's lane) or the goal lane is out of reach of the lanes it can enter the last edge by.
        """
        reach, pos = frozenset({start_lane}), float(start_pos)
        for k, edge in enumerate(route[:-1]):
            changes = int(max(self.edge_length[edge] - pos - cutoff_m, 0.0) // begin_m) if begin_m > 0 else len(self.lanes)
            if changes:
                reach = frozenset(lane for lane in self.edge_lanes[edge] if self.changes_into(lane, reach) <= changes)
            reach = frozenset(c.to_lane for c in self.links(edge, route[k + 1]) if c.from_lane in reach)
            if not reach:
                return False
            pos = 0.0
        return goal_lane in self._goal_lanes(tuple(route), reach, goal_pos, start_pos, change_m, change_s)

    @functools.lru_cache(maxsize=4096)  # noqa: B019 - networks live as long as the process (load_road_network)
    def _route_lanes(self, route: tuple[str, ...], goal_lane: str, goal_pos: float | None, change_m: float,
                     change_s: float, cutoff_m: float) -> tuple[frozenset[str], ...]:
        good = [frozenset({goal_lane})]
        for k in range(len(route) - 2, -1, -1):
            edge, to_edge = route[k], route[k + 1]
            last = k + 1 == len(route) - 1
            room = goal_pos if last and goal_pos is not None else self.edge_length[to_edge] - cutoff_m
            targets = [self.lanes[ln].index for ln in good[-1]]
            links = self.links(edge, to_edge)
            changes, fits = {}, {}
            for c in links:
                to_lane = self.lanes[c.to_lane]
                changes[c] = min((abs(to_lane.index - t) for t in targets), default=0)
                fits[c] = changes[c] * max(change_m, change_s * to_lane.speed) <= max(room, 0.0)
            fewest = min(changes.values(), default=0)
            good.append(frozenset(c.from_lane for c in links if fits[c] or changes[c] == fewest))
        return tuple(reversed(good))

    def neighbour_lane(self, lane_id: str, side: int) -> str | None:
        """The drivable lane ``side`` = +1 (left) or -1 (right) of ``lane_id``, else None."""
        lane = self.lanes.get(lane_id)
        if lane is None:
            return None
        ids = self.edge_lanes[lane.edge]
        pos = ids.index(lane_id) + side
        return ids[pos] if 0 <= pos < len(ids) else None

    def follow(self, lane_id: str, next_edge: str | None, into: frozenset[str] = frozenset()) -> str | None:
        """The lane after ``lane_id`` on the way to ``next_edge`` (internal lanes included).

        Where several links of ``lane_id`` lead onto ``next_edge`` (a lane that fans out), the one
        landing fewest lane changes from the lanes ``into`` (lanes of ``next_edge``: the route's
        lanes there, :meth:`route_lanes`), the first of those; without ``into``, the first. Falls
        back to the first successor when no link leads to ``next_edge``; None at a dead end.
        """
        options = self.lane_next.get(lane_id, ())
        steps = [step for step, edge in options if edge == next_edge]
        if len(steps) > 1 and into:
            return min(steps, key=lambda step: self.changes_into(self._link_end.get(step, step), into))
        if steps:
            return steps[0]
        return options[0][0] if options else None

    def changes_into(self, lane_id: str, into: frozenset[str] | None) -> int:
        """Lane changes from ``lane_id`` to the nearest lane of ``into`` on its edge (0 without ``into``)."""
        lane = self.lanes.get(lane_id)
        if lane is None:
            return len(self.lanes)
        return min((abs(self.lanes[t].index - lane.index) for t in into or () if t in self.lanes), default=0)

    def rightmost_lane(self, edge: str) -> str:
        """The rightmost drivable lane of ``edge``."""
        return self.edge_lanes[edge][0]

    def position(self, lane_id: str, pos: float) -> np.ndarray:
        """Point (2,) [m] at SUMO lane position ``pos`` [m] (0 .. ``length``) of a lane: like SUMO,
        the position is scaled onto the drawn shape (by ``shape_length / length``)."""
        lane = self.lane(lane_id)
        return point_along(lane.shape, pos * (lane.shape_length / lane.length if lane.length > 0 else 1.0))

    # ------------------------------------------------------------- routes
    def link_lanes(self, link: Connection) -> tuple[str, ...]:
        """The internal (junction) lanes a link runs over, in driving order; () if it has none."""
        lanes, lane = [], link.via
        while lane in self.internal_lanes:
            lanes.append(lane)
            lane = self.follow(lane, link.to_edge)
        return tuple(lanes)

    def link_shape(self, link: Connection) -> np.ndarray:
        """The centreline (N, 2) [m] of a link's junction lanes, from the stop line on (empty if none)."""
        lanes = self.link_lanes(link)
        if not lanes:
            return np.zeros((0, 2))
        return np.vstack([self.lane(ln).shape for ln in lanes])

    @functools.lru_cache(maxsize=4096)  # noqa: B019 - networks live as long as the process (load_road_network)
    def link_conflicts(self, link: Connection) -> tuple[LinkConflict, ...]:
        """The links of the same junction (from other lanes) whose centreline comes within
        ``CONFLICT_WIDTH_M`` of ``link``'s: crossings, merges, close passes (pure geometry of the
        junction lanes; who has the right of way is the links' state or signal)."""
        node = self.edge_from_to[link.from_edge][1]
        shape = self.link_shape(link)
        if len(shape) < 2:
            return ()
        out = []
        for edge, (_, to_node) in self.edge_from_to.items():
            if to_node != node:
                continue
            for foe in self.connections[edge]:
                foe_shape = self.link_shape(foe)
                if foe.from_lane == link.from_lane or len(foe_shape) < 2:
                    continue
                zone, foe_zone = _close_stretch(shape, foe_shape), _close_stretch(foe_shape, shape)
                if zone is not None and foe_zone is not None:
                    out.append(LinkConflict(foe, *zone, *foe_zone))
        return tuple(out)

    def crossing_clearance(self, car_width_m: float = 2.0, pedestrian_width_m: float = 0.5) -> tuple[float, str, str]:
        """The smallest gap [m] between a car ``car_width_m`` wide on the centre of a drivable junction lane
        and a pedestrian ``pedestrian_width_m`` wide waiting to cross at a junction of that lane: on the
        kerb line across either end of a crossing, spread over its width (where SUMO puts them).
        Returns (gap, junction lane, crossing); (inf, "", "") without crossings. A negative gap: the car
        cannot turn past someone waiting there (with 4 m crossings and 5-point junction lanes the towns'
        right turns passed 0.35-1.25 m into them, and a lawful car waited behind them for a whole cycle)."""
        best = (float("inf"), "", "")
        waiting: dict[str, list[tuple[str, np.ndarray]]] = {}
        for crossing in self.crossings.values():
            node = crossing.id[1:].rsplit("_", 1)[0]
            half = max(crossing.width / 2 - pedestrian_width_m / 2, 0.0)
            for end, inner in ((crossing.shape[0], crossing.shape[1]), (crossing.shape[-1], crossing.shape[-2])):
                along = (inner - end) / max(float(np.hypot(*(inner - end))), 1e-9)
                across = np.array([-along[1], along[0]])
                points = end + np.linspace(-half, half, 9)[:, None] * across
                waiting.setdefault(node, []).append((crossing.id, points))
        for conns in self._drivable_links.values():
            for link in conns:
                for lane_id in self.link_lanes(link):
                    shape = self.internal_lanes[lane_id].shape
                    node = lane_id[1:].rsplit("_", 2)[0]
                    for crossing_id, points in waiting.get(node, ()):
                        gap = float(np.min(_project_points(shape, points)[1])) - (car_width_m + pedestrian_width_m) / 2
                        if gap < best[0]:
                            best = (gap, lane_id, crossing_id)
        return best

    @functools.lru_cache(maxsize=4096)  # noqa: B019 - networks live as long as the process (load_road_network)
    def link_crossings(self, link: Connection) -> tuple[tuple[Crossing, float, float], ...]:
        """The pedestrian crossings of the junction that ``link`` passes over or beside: (crossing,
        start, end [m] along the link's junction lanes of the stretch within half the crossing's
        width and a car's half width and a margin of the crossing's centreline)."""
        node = self.edge_from_to[link.from_edge][1]
        shape = self.link_shape(link)
        if len(shape) < 2:
            return ()
        out = []
        for crossing in self.crossings.values():
            if not crossing.id.startswith(f":{node}_"):
                continue
            zone = _close_stretch(shape, crossing.shape, width_m=crossing.width / 2 + 1.2)
            if zone is not None:
                out.append((crossing, *zone))
        return tuple(out)

    def route_link(self, edge: str, to_edge: str, lane_id: str, allowed: frozenset[str] | None = None) -> Connection:
        """The link from ``edge`` onto ``to_edge`` that a car in ``lane_id`` (a lane of ``edge``) takes:
        its own lane's link where it has one (the one that keeps the lane index, if several), else
        the link of the nearest lane that has one (the car changes lanes on ``edge``). Only links
        from the ``allowed`` lanes count, where any is (see :meth:`route_lanes`)."""
        links = self.links(edge, to_edge)
        if not links:
            raise ValueError(f"no link from {edge!r} to {to_edge!r} in {self.path.name}")
        links = tuple(c for c in links if allowed is None or c.from_lane in allowed) or links
        index = self.lane(lane_id).index
        return min(links, key=lambda c: (abs(self.lanes[c.from_lane].index - index),
                                         abs(self.lanes[c.to_lane].index - self.lanes[c.from_lane].index),
                                         c.to_lane))

    def route_path(self, route: tuple[str, ...] | list[str], start_lane: str | None = None,
                   goal_lane: str | None = None, goal_pos: float | None = None) -> RoutePath:
        """The lanes a car drives along ``route`` (see :class:`RoutePath`), starting in ``start_lane``
        (default: the rightmost lane of route[0]): on each edge the lane it leaves the edge by (the
        from-lane of the link ``route_link`` picks for the lane it entered by, among the lanes that
        lead on to ``goal_lane`` at ``goal_pos`` [m]: :meth:`route_lanes`), the junction lanes of
        that link, and on the last edge ``goal_lane`` (default: the lane the last link leads to)."""
        route = tuple(route)
        lane = start_lane or self.rightmost_lane(route[0])
        if self.lane(lane).edge != route[0]:
            raise ValueError(f"start lane {lane!r} is not on the route's first edge {route[0]!r}")
        if goal_lane is not None and self.lane(goal_lane).edge != route[-1]:
            raise ValueError(f"goal lane {goal_lane!r} is not on the route's last edge {route[-1]!r}")
        good = self.route_lanes(route, goal_lane, goal_pos) if goal_lane is not None else (None,) * len(route)
        lanes, edge_index, junction_index = [lane], [0], []
        for k, (edge, to_edge) in enumerate(zip(route[:-1], route[1:])):
            link = self.route_link(edge, to_edge, lane, good[k])
            lanes[-1] = link.from_lane
            junction = self.link_lanes(link)
            junction_index.append(range(len(lanes), len(lanes) + len(junction)))
            lane = link.to_lane
            lanes.extend(junction)
            edge_index.append(len(lanes))
            lanes.append(lane)
        if goal_lane is not None:
            lanes[-1] = goal_lane
        offsets = np.concatenate([[0.0], np.cumsum([self.lane(ln).shape_length for ln in lanes])])
        junctions = tuple(tuple(JunctionLane(lanes[i], self.lane(lanes[i]).shape, float(offsets[i])) for i in ids)
                          for ids in junction_index)
        edge_lanes = [self.lane(lanes[i]) for i in edge_index]
        return RoutePath(route, tuple(lanes), offsets, offsets[edge_index], offsets[np.add(edge_index, 1)],
                         np.array([ln.shape_length / ln.length if ln.length > 0 else 1.0 for ln in edge_lanes]),
                         junctions)

    def route_length(self, route: tuple[str, ...], start_pos: float, goal_pos: float,
                     start_lane: str | None = None, goal_lane: str | None = None) -> float:
        """Length [m] a car drives from ``start_pos`` on ``start_lane`` to ``goal_pos`` on ``goal_lane``
        (SUMO lane positions [m] on route[0] and route[-1]; lanes as in :meth:`route_path`), along the
        route's lanes and the junction lanes between them."""
        return self.route_path(route, start_lane, goal_lane, goal_pos).length(start_pos, goal_pos)


@dataclass(frozen=True)
class JunctionLane:
    """An internal lane of a :class:`RoutePath`: id, shape (N, 2) [m], ``start`` [m] = distance
    from the start of the route's first lane to the start of this lane."""

    id: str
    shape: np.ndarray
    start: float


@dataclass(frozen=True)
class RoutePath:
    """The lanes a car drives along an edge route, junction (internal) lanes included.

    Distances are along the lanes' drawn shapes [m] (``Lane.shape_length``: what a car drives, what
    the world's odometer measures); SUMO lane positions are mapped onto them as SUMO does. E route
    edges, L lanes.

    Attributes:
        route: (E,) edge ids.
        lanes: (L,) lane ids in driving order: one lane of each route edge (the lane the car leaves
            it by; on the last edge the goal lane) and, between two edges, the internal lanes of the
            link joining them (``RoadNetwork.route_link``). Each lane leads into the next, or onto
            its edge where the car changes lanes on that edge.
        offsets: (L + 1,) [m] distance from the start of ``lanes[0]`` to the start of each lane;
            ``offsets[-1]`` is the length of all of them.
        edge_start / edge_end: (E,) [m] distance from the start of ``lanes[0]`` to the start / end
            of each route edge's lane; junction k spans ``edge_end[k]`` .. ``edge_start[k + 1]``.
        edge_scale: (E,) drawn length per SUMO lane position of each route edge's lane [m/m].
        junctions: (E - 1,) the internal lanes between route[k] and route[k + 1] (may be none).
    """

    route: tuple[str, ...]
    lanes: tuple[str, ...]
    offsets: np.ndarray
    edge_start: np.ndarray
    edge_end: np.ndarray
    edge_scale: np.ndarray
    junctions: tuple[tuple[JunctionLane, ...], ...]

    def position(self, edge_index: int, lane_pos: float) -> float:
        """Distance [m] from the start of the route to SUMO lane position ``lane_pos`` [m] on any lane
        of route[edge_index] (the lanes of an edge share one SUMO length)."""
        return float(self.edge_start[edge_index] + lane_pos * self.edge_scale[edge_index])

    def length(self, start_pos: float, goal_pos: float) -> float:
        """Driven length [m] from SUMO lane position ``start_pos`` [m] on the first edge to
        ``goal_pos`` [m] on the last."""
        return self.position(len(self.route) - 1, goal_pos) - self.position(0, start_pos)

    def junction_position(self, edge_index: int, point: np.ndarray) -> float:
        """Distance [m] from the start of the route to a point (2,) [m] in the junction after
        route[edge_index]: its projection on that junction's lanes, clipped to the junction."""
        lo, hi = float(self.edge_end[edge_index]), float(self.edge_start[edge_index + 1])
        best_m, at = np.inf, lo
        for lane in self.junctions[edge_index]:
            arc_m, off_m = project_on_polyline(lane.shape, point)
            if off_m < best_m:
                best_m, at = off_m, lane.start + arc_m
        return float(np.clip(at, lo, hi))


# ---------------------------------------------------------------- readers (a sumolib net -> tables)
def _lane(ln, edge_id: str) -> Lane:
    return Lane(id=ln.getID(), edge=edge_id, index=ln.getIndex(), shape=np.asarray(ln.getShape(), dtype=float)[:, :2],
                length=float(ln.getLength()), width=float(ln.getWidth()), speed=float(ln.getSpeed()))


def read_lanes(net) -> tuple[dict[str, Lane], dict[str, Lane], dict[str, tuple[str, ...]], dict[str, tuple[str, str]]]:
    """The drivable lanes (those allowing ``passenger``) of a sumolib net: (lanes of normal edges,
    junction lanes, edge -> its lane ids, edge -> (from node, to node)); edges without a drivable lane
    are left out."""
    lanes: dict[str, Lane] = {}
    internal: dict[str, Lane] = {}
    edge_lanes: dict[str, tuple[str, ...]] = {}
    edge_from_to: dict[str, tuple[str, str]] = {}
    for edge in net.getEdges(withInternal=True):
        drivable = [_lane(ln, edge.getID()) for ln in edge.getLanes() if ln.allows("passenger")]
        if not drivable:
            continue
        if edge.getFunction() == "internal":
            internal.update((lane.id, lane) for lane in drivable)
            continue
        lanes.update((lane.id, lane) for lane in drivable)
        edge_lanes[edge.getID()] = tuple(lane.id for lane in drivable)
        edge_from_to[edge.getID()] = (edge.getFromNode().getID(), edge.getToNode().getID())
    return lanes, internal, edge_lanes, edge_from_to


def read_walkable_edges(net) -> tuple[str, ...]:
    """Road edges with a drivable and a walkable lane, longer than ``WALK_SPAWN_MIN_M``, sorted."""
    return tuple(sorted(
        e.getID() for e in net.getEdges(withInternal=False)
        if e.getFunction() == "" and any(ln.allows("pedestrian") for ln in e.getLanes())
        and any(ln.allows("passenger") for ln in e.getLanes()) and e.getLength() > WALK_SPAWN_MIN_M))


def read_connections(net, lanes: Mapping[str, Lane], edge_lanes: Mapping[str, tuple[str, ...]]
                     ) -> dict[str, tuple[Connection, ...]]:
    """Every link from a drivable lane to a drivable lane, by the normal edge it leaves."""
    connections: dict[str, tuple[Connection, ...]] = {}
    for edge_id in edge_lanes:
        links = []
        for to_edge, conns in net.getEdge(edge_id).getOutgoing().items():
            if to_edge.getID() not in edge_lanes:
                continue
            links += [Connection(from_edge=edge_id, from_lane=c.getFromLane().getID(), to_edge=to_edge.getID(),
                                 to_lane=c.getToLane().getID(), via=c.getViaLaneID() or "", direction=c.getDirection(),
                                 tls=c.getTLSID() or "", link_index=int(c.getTLLinkIndex()), state=c.getState() or "M")
                      for c in conns if c.getFromLane().getID() in lanes and c.getToLane().getID() in lanes]
        connections[edge_id] = tuple(links)
    return connections


def _final_edge(net, lane_id: str, lanes: Mapping[str, Lane], internal: Mapping[str, Lane]) -> str:
    """The normal edge a (possibly internal) lane leads onto ("" where its junction lanes end)."""
    while lane_id in internal:
        outgoing = net.getLane(lane_id).getOutgoing()
        if not outgoing:
            return ""
        lane_id = outgoing[0].getViaLaneID() or outgoing[0].getToLane().getID()
    return lanes[lane_id].edge if lane_id in lanes else ""


def read_lane_next(net, lanes: Mapping[str, Lane], internal: Mapping[str, Lane]
                   ) -> dict[str, tuple[tuple[str, str], ...]]:
    """Lane (normal or junction) -> per link to a drivable lane: (the next lane, its first junction lane where
    it has one; the normal edge that leads onto)."""
    lane_next: dict[str, tuple[tuple[str, str], ...]] = {}
    for lane_id in [*lanes, *internal]:
        steps = [c.getViaLaneID() or c.getToLane().getID() for c in net.getLane(lane_id).getOutgoing()
                 if c.getToLane().getID() in lanes or c.getToLane().getID() in internal]
        lane_next[lane_id] = tuple((step, _final_edge(net, step, lanes, internal)) for step in steps)
    return lane_next


def read_junction_shapes(net) -> dict[str, np.ndarray]:
    """Node -> its polygon (N, 2) [m], for nodes whose shape has three or more points."""
    return {node.getID(): np.asarray(node.getShape(), dtype=float)[:, :2]
            for node in net.getNodes() if len(node.getShape()) >= 3}


def read_crossings(net, net_path: Path) -> dict[str, Crossing]:
    """Pedestrian crossings by edge id, with the signal of each (:func:`_crossing_signals`)."""
    signals = _crossing_signals(net_path)
    crossings: dict[str, Crossing] = {}
    for edge in net.getEdges(withInternal=True):
        if edge.getFunction() != "crossing" or not edge.getLanes():
            continue
        lane = edge.getLanes()[0]
        ends = tuple(e.getID() for e in (*edge.getIncoming(), *edge.getOutgoing()))
        tls, index = signals.get(edge.getID(), ("", -1))
        crossings[edge.getID()] = Crossing(edge.getID(), np.asarray(lane.getShape(), dtype=float)[:, :2],
                                           float(lane.getWidth()), ends, tls, index)
    return crossings


def _crossing_signals(net_path: Path) -> dict[str, tuple[str, int]]:
    """Crossing edge id -> (traffic light, link index) of its pedestrian signal, read off the net
    file's connections onto crossings (sumolib skips them unless it reads every pedestrian link)."""
    import xml.etree.ElementTree as ET

    out = {}
    for _, elem in ET.iterparse(str(net_path)):
        if elem.tag == "connection" and elem.get("tl") and elem.get("to", "").startswith(":"):
            out.setdefault(elem.get("to"), (elem.get("tl"), int(elem.get("linkIndex", -1))))
        elem.clear()
    return out


def _close_stretch(shape: np.ndarray, other: np.ndarray, spacing: float = 0.5,
                   width_m: float = CONFLICT_WIDTH_M) -> tuple[float, float] | None:
    """The first stretch (start, end) [m] along a polyline (N, 2) that lies within ``width_m`` of
    another (M, 2); None if none does."""
    s, points = _sample_polyline(shape, spacing)
    _, dist = _project_points(other, points)
    close = np.flatnonzero(dist < width_m)
    if not len(close):
        return None
    run = close[: int(np.argmax(np.diff(np.append(close, close[-1] + 2)) > 1)) + 1]
    return float(s[run[0]]), float(s[run[-1]])


def _sample_polyline(shape: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Arc lengths (M,) [m] and points (M, 2) every ``spacing`` [m] along a polyline, ends included."""
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(shape, axis=0).T))])
    s = np.append(np.arange(0.0, cum[-1], spacing), cum[-1])
    return s, np.column_stack([np.interp(s, cum, shape[:, 0]), np.interp(s, cum, shape[:, 1])])


def _project_points(shape: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For points (M, 2): arc length [m] of the nearest point of the polyline (N, 2) and the distance to it [m]."""
    a, b = shape[:-1], shape[1:]
    ab = b - a
    seg_len2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
    t = np.clip(np.einsum("mij,ij->mi", points[:, None, :] - a[None], ab) / seg_len2, 0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]
    dist = np.hypot(*(points[:, None, :] - nearest).transpose(2, 0, 1))
    i = np.argmin(dist, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(np.sqrt(seg_len2))])
    rows = np.arange(len(points))
    return cum[i] + t[rows, i] * np.sqrt(seg_len2[i]), dist[rows, i]


def project_on_polyline(shape: np.ndarray, point: np.ndarray) -> tuple[float, float]:
    """(arc length [m] of the nearest point of a polyline (N, 2) to ``point`` (2,), distance [m] to it)."""
    seg = np.diff(shape, axis=0)
    seg_len2 = np.einsum("ij,ij->i", seg, seg)
    t = np.clip(np.einsum("ij,ij->i", point - shape[:-1], seg) / np.maximum(seg_len2, 1e-12), 0.0, 1.0)
    nearest = shape[:-1] + t[:, None] * seg
    dist = np.hypot(*(nearest - point).T)
    i = int(np.argmin(dist))
    seg_len = np.sqrt(seg_len2)
    return float(seg_len[:i].sum() + t[i] * seg_len[i]), float(dist[i])


def sharpest_turn_radius(shape: np.ndarray, window_m: float = TURN_WINDOW_M, spacing: float = 0.25) -> float:
    """Tightest radius [m] of a polyline (N, 2) [m]: ``window_m`` over the largest heading change [rad]
    within any ``window_m`` of its arc (the whole arc when shorter); inf where it does not turn."""
    seg = np.hypot(*np.diff(shape, axis=0).T)
    pts = shape[np.append(True, seg > 1e-9)]
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    if len(pts) < 2 or arc[-1] <= spacing:
        return float("inf")
    s = np.append(np.arange(0.0, arc[-1], spacing), arc[-1])
    x, y = np.interp(s, arc, pts[:, 0]), np.interp(s, arc, pts[:, 1])
    heading = np.unwrap(np.arctan2(np.diff(y), np.diff(x)))
    k = min(max(int(round(window_m / spacing)), 1), len(heading) - 1)
    if k < 1:
        return float("inf")
    turn = float(np.max(np.abs(heading[k:] - heading[:-k])))
    return k * spacing / turn if turn > 1e-9 else float("inf")


def point_along(shape: np.ndarray, pos: float) -> np.ndarray:
    """Point (2,) at arc length ``pos`` [m] along a polyline (N, 2), clipped to its ends."""
    seg = np.diff(shape, axis=0)
    seg_len = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    pos = float(np.clip(pos, 0.0, cum[-1]))
    i = int(np.clip(np.searchsorted(cum, pos, side="right") - 1, 0, len(seg) - 1))
    frac = (pos - cum[i]) / seg_len[i] if seg_len[i] > 0 else 0.0
    return shape[i] + frac * seg[i]


def load_road_network(net_path: str) -> RoadNetwork:
    """The (process-wide cached) RoadNetwork of a net file; a file written again since it was read (a map
    imported again with ``force``, which replaces the file) is read again; FileNotFoundError once it is gone."""
    stat = os.stat(net_path)
    return _read_road_network(net_path, stat.st_ino, stat.st_mtime_ns, stat.st_size)


@functools.lru_cache(maxsize=16)
def _read_road_network(net_path: str, inode: int, mtime_ns: int, size: int) -> RoadNetwork:
    return RoadNetwork.from_sumo(net_path)
