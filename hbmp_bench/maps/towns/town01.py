"""Town01: a rectangle (390 m x 325 m) with three internal rows, T-junctions only.

"Brick wall" layout: four east-west rows (y = 0, 108, 216, 325 m) between the west
(x = 0) and east (x = 390 m) sides; north-south connectors between neighbouring rows are
staggered so that every junction has three legs. The four outer corners are rounded
edge shapes (radius 15 m), not nodes. All roads: one lane per direction, 13.89 m/s.
"""

from ..spec import Node, Road, TownSpec

T, P = "traffic_light", "priority"

_NODES = (
    # id, x (m), y (m), type
    ("W1", 0, 108, P), ("W2", 0, 216, P), ("E1", 390, 108, P), ("E2", 390, 216, P),
    # connectors of the southern band (y 0..108)
    ("S1a", 130, 0, T), ("S1b", 130, 108, T), ("S2a", 260, 0, T), ("S2b", 260, 108, T),
    # connectors of the middle band (y 108..216)
    ("M1a", 65, 108, T), ("M1b", 65, 216, T), ("M2a", 195, 108, T), ("M2b", 195, 216, T),
    ("M3a", 325, 108, T), ("M3b", 325, 216, T),
    # connectors of the northern band (y 216..325)
    ("N1a", 130, 216, T), ("N1b", 130, 325, T), ("N2a", 260, 216, T), ("N2b", 260, 325, T),
)

_ROADS = (
    # from, to, rounded corners on the way
    ("W1", "S1a", ((0, 0),)), ("S1a", "S2a", ()), ("S2a", "E1", ((390, 0),)),          # y=0
    ("W1", "M1a", ()), ("M1a", "S1b", ()), ("S1b", "M2a", ()), ("M2a", "S2b", ()),     # y=108
    ("S2b", "M3a", ()), ("M3a", "E1", ()),
    ("W2", "M1b", ()), ("M1b", "N1a", ()), ("N1a", "M2b", ()), ("M2b", "N2a", ()),     # y=216
    ("N2a", "M3b", ()), ("M3b", "E2", ()),
    ("W2", "N1b", ((0, 325),)), ("N1b", "N2b", ()), ("N2b", "E2", ((390, 325),)),      # y=325
    ("W1", "W2", ()), ("E1", "E2", ()),                                                # sides
    ("S1a", "S1b", ()), ("S2a", "S2b", ()),                                            # connectors
    ("M1a", "M1b", ()), ("M2a", "M2b", ()), ("M3a", "M3b", ()),
    ("N1a", "N1b", ()), ("N2a", "N2b", ()),
)

SPEC = TownSpec(
    name="Town01",
    nodes=tuple(Node(i, x, y, t) for i, x, y, t in _NODES),
    roads=tuple(Road(a, b, lanes=1, corners=c, radius=15.0) for a, b, c in _ROADS),
)
