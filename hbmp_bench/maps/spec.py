"""Declarative description of a town: nodes, roads, roundabouts.

A :class:`TownSpec` is plain data. One general builder (:mod:`hbmp_bench.maps.builder`)
turns any spec into SUMO plain XML and then into a ``.net.xml`` with netconvert.

Units: coordinates and lengths in metres (x east, y north), speeds in m/s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from hbmp_bench.errors import ConfigError

Point = tuple[float, float]

#: Default town speed limit, m/s (50 km/h).
TOWN_SPEED = 13.89
#: Highway speed limit, m/s (90 km/h).
HIGHWAY_SPEED = 25.0
#: Ramp speed limit, m/s (60 km/h).
RAMP_SPEED = 16.67
#: Width of the sidewalk added to town roads, m.
SIDEWALK_WIDTH = 2.0


@dataclass(frozen=True)
class Node:
    """A junction of the town.

    Attributes:
        id: node id in the generated net.
        x, y: position, m.
        type: netconvert node type, ``"priority"`` or ``"traffic_light"``.
    """

    id: str
    x: float
    y: float
    type: str = "priority"


@dataclass(frozen=True)
class Road:
    """A road between two nodes, two-way unless ``oneway``.

    Attributes:
        a, b: ids of the start and end node (the forward direction is a -> b).
        lanes: vehicle lanes per direction.
        speed: speed limit, m/s.
        corners: points (m) where the road turns on its way from a to b; each corner is
            rounded with an arc of ``radius`` m (the corner itself is no node).
        radius: radius of the rounded corners, m; 0 keeps ``corners`` as plain shape
            points (e.g. an arc made with :func:`arc_points`).
        oneway: only the a -> b edge is built.
        elevation: height [m] of every shape point between the two end nodes (which stay at 0):
            a bridge over the roads it crosses; 0 keeps the road flat.
        sidewalk: add a sidewalk of :data:`SIDEWALK_WIDTH` m to each edge.
        id: edge id of the forward edge; default ``"a_b"``. The backward edge gets the
            id of the forward edge with a leading ``-``.
    """

    a: str
    b: str
    lanes: int = 1
    speed: float = TOWN_SPEED
    corners: tuple[Point, ...] = ()
    radius: float = 12.0
    oneway: bool = False
    sidewalk: bool = True
    id: str | None = None
    elevation: float = 0.0

    @property
    def edge_id(self) -> str:
        """Id of the forward (a -> b) edge."""
        return self.id or f"{self.a}_{self.b}"


@dataclass(frozen=True)
class Roundabout:
    """A roundabout: the ring's node ids in driving order (counter-clockwise)."""

    nodes: tuple[str, ...]


@dataclass(frozen=True)
class TownSpec:
    """Everything the builder needs to make one town's net.

    Attributes:
        name: town name (the net is ``<name>.net.xml``).
        nodes / roads / roundabouts: the layout.
        green_s: vehicle green of each main phase of the town's traffic lights [s]
            (:mod:`hbmp_bench.maps.signals`: long enough to clear the suites' queues, short
            enough that a lawful driver meets every episode's timeout).
    """

    name: str
    nodes: tuple[Node, ...]
    roads: tuple[Road, ...]
    roundabouts: tuple[Roundabout, ...] = field(default=())
    green_s: int = 20

    def __post_init__(self):
        if self.green_s < 5:
            raise ConfigError(f"{self.name}: green_s must be >= 5 [s], got {self.green_s}")

    def node(self, node_id: str) -> Node:
        """The node with id ``node_id`` (KeyError if none)."""
        for n in self.nodes:
            if n.id == node_id:
                return n
        raise KeyError(node_id)


def rounded_polyline(points: list[Point], radius: float, steps: int = 6) -> list[Point]:
    """Replace each interior vertex of ``points`` by a circular arc of ``radius`` m.

    The arc is tangent to both adjacent segments; it is shrunk where a segment is too
    short to hold it. ``steps`` arc segments per corner. Returns a new list of points (m)
    that starts and ends with the original end points.
    """
    if len(points) < 3 or radius <= 0:
        return list(points)
    out: list[Point] = [points[0]]
    for i in range(1, len(points) - 1):
        p0, p1, p2 = points[i - 1], points[i], points[i + 1]
        d1 = (p0[0] - p1[0], p0[1] - p1[1])
        d2 = (p2[0] - p1[0], p2[1] - p1[1])
        l1, l2 = math.hypot(*d1), math.hypot(*d2)
        u1 = (d1[0] / l1, d1[1] / l1)
        u2 = (d2[0] / l2, d2[1] / l2)
        cos_t = max(-1.0, min(1.0, u1[0] * u2[0] + u1[1] * u2[1]))
        theta = math.acos(cos_t)  # angle between the two legs at the corner
        if theta < 1e-6 or abs(theta - math.pi) < 1e-6:
            out.append(p1)
            continue
        tan_dist = radius / math.tan(theta / 2.0)
        tan_dist = min(tan_dist, 0.45 * l1, 0.45 * l2)
        r = tan_dist * math.tan(theta / 2.0)
        t1 = (p1[0] + u1[0] * tan_dist, p1[1] + u1[1] * tan_dist)
        t2 = (p1[0] + u2[0] * tan_dist, p1[1] + u2[1] * tan_dist)
        bis = (u1[0] + u2[0], u1[1] + u2[1])
        bl = math.hypot(*bis)
        c_dist = r / math.sin(theta / 2.0)
        c = (p1[0] + bis[0] / bl * c_dist, p1[1] + bis[1] / bl * c_dist)
        a1 = math.atan2(t1[1] - c[1], t1[0] - c[0])
        a2 = math.atan2(t2[1] - c[1], t2[0] - c[0])
        sweep = (a2 - a1 + math.pi) % (2.0 * math.pi) - math.pi
        for k in range(steps + 1):
            a = a1 + sweep * k / steps
            out.append((c[0] + r * math.cos(a), c[1] + r * math.sin(a)))
    out.append(points[-1])
    return out


def arc_points(center: Point, radius: float, start_deg: float, end_deg: float,
               steps: int = 6) -> tuple[Point, ...]:
    """Interior points (m) of a circular arc from ``start_deg`` to ``end_deg`` (degrees,
    counter-clockwise from east when end > start), end points excluded."""
    pts = []
    for k in range(1, steps):
        a = math.radians(start_deg + (end_deg - start_deg) * k / steps)
        pts.append((center[0] + radius * math.cos(a), center[1] + radius * math.sin(a)))
    return tuple(pts)
