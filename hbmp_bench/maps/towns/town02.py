"""Town02: a small Town01 (195 m x 180 m), T-junctions only.

Same "brick wall" idea as Town01: four east-west rows (y = 0, 60, 120, 180 m) between
the west (x = 0) and east (x = 195 m) sides, staggered north-south connectors, rounded
outer corners (radius 12 m). One lane per direction, 13.89 m/s.

Lights: 12 s greens (a 34.8 s cycle), not the 20 s of the larger towns. Signals stand 39-60 m
apart, and the CoRL2017 timeouts of the short routes (~100 m, ~45 s) leave a lawful driver no
more: with 14 s greens some episodes' lawful travel time reaches the timeout
(:mod:`hbmp_bench.scenarios.lawful`). 12 s still clear a queue of 5 cars, more than a lane holds
in the densest suite with 99 % probability.
"""

from ..spec import Node, Road, TownSpec

T, P = "traffic_light", "priority"

_NODES = (
    # id, x (m), y (m), type
    ("W1", 0, 60, P), ("W2", 0, 120, P), ("E1", 195, 60, T), ("E2", 195, 120, T),
    ("S1a", 39, 0, T), ("S1b", 39, 60, T), ("S2a", 117, 0, T), ("S2b", 117, 60, T),
    ("M1a", 78, 60, T), ("M1b", 78, 120, T), ("M2a", 156, 60, T), ("M2b", 156, 120, T),
    ("N1a", 39, 120, T), ("N1b", 39, 180, T), ("N2a", 117, 120, T), ("N2b", 117, 180, T),
)

_ROADS = (
    # from, to, rounded corners on the way
    ("W1", "S1a", ((0, 0),)), ("S1a", "S2a", ()), ("S2a", "E1", ((195, 0),)),          # y=0
    ("W1", "S1b", ()), ("S1b", "M1a", ()), ("M1a", "S2b", ()), ("S2b", "M2a", ()),     # y=60
    ("M2a", "E1", ()),
    ("W2", "N1a", ()), ("N1a", "M1b", ()), ("M1b", "N2a", ()), ("N2a", "M2b", ()),     # y=120
    ("M2b", "E2", ()),
    ("W2", "N1b", ((0, 180),)), ("N1b", "N2b", ()), ("N2b", "E2", ((195, 180),)),      # y=180
    ("W1", "W2", ()), ("E1", "E2", ()),                                                # sides
    ("S1a", "S1b", ()), ("S2a", "S2b", ()),                                            # connectors
    ("M1a", "M1b", ()), ("M2a", "M2b", ()),
    ("N1a", "N1b", ()), ("N2a", "N2b", ()),
)

SPEC = TownSpec(
    name="Town02",
    nodes=tuple(Node(i, x, y, t) for i, x, y, t in _NODES),
    roads=tuple(Road(a, b, lanes=1, corners=c, radius=12.0) for a, b, c in _ROADS),
    green_s=12,
)
