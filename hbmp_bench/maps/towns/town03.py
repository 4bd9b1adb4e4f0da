"""Town03: a multi-lane town (352 m x 363 m) with a roundabout and a 5-leg junction.

The layout is drawn on a 320 x 330 grid (the numbers below) scaled by ``SCALE`` = 1.1 to
metres. A perimeter road (rounded corners except the north-east one, which is a junction)
encloses a 3 x 3 block grid: inner roads at x = 90, 230 and y = 95, 235. The central
block holds a two-lane roundabout (centre (160, 165), radius 25) fed by four
approaches. The south inner road (y = 95) is a 3-lane avenue, side streets have one
lane, all other roads two lanes per direction. The junction at (230, 235) is
signalised with five legs (a diagonal to the north-east corner). All roads 13.89 m/s.

Lights: 12 s greens, not the 20 s of Town01/04/05. The five-leg junction needs three main phases
and a pedestrian phase (a 62 s cycle with 12 s greens, 86 s with 20 s), and routes of ~100 m
through it have ~47 s CoRL2017 timeouts: with 14 s greens a lawful driver misses some
(:mod:`hbmp_bench.scenarios.lawful`).
"""

from ..spec import Node, Road, Roundabout, TownSpec, arc_points

T, P = "traffic_light", "priority"
SCALE = 1.1                             # grid units -> m
CENTER, RADIUS = (160.0, 165.0), 25.0   # roundabout, grid units

_NODES = (
    # id, x, y (grid units), type -- perimeter, counter-clockwise from the south-west
    ("Pb45", 45, 0, P), ("Pb90", 90, 0, T), ("Pb125", 125, 0, P), ("Pb230", 230, 0, T),
    ("Pb275", 275, 0, P), ("Pr95", 320, 95, T), ("Pr200", 320, 200, P),
    ("Pr235", 320, 235, T), ("NE", 320, 330, P), ("Pt230", 230, 330, T),
    ("Pt195", 195, 330, P), ("Pt90", 90, 330, P), ("Pt45", 45, 330, P),
    ("Pl235", 0, 235, P), ("Pl130", 0, 130, P), ("Pl95", 0, 95, T),
    # inner grid: crosses (X), side-street tees (I), roundabout approaches (A)
    ("X90_95", 90, 95, T), ("X230_95", 230, 95, T), ("X90_235", 90, 235, T),
    ("X230_235", 230, 235, T),
    ("I45_95", 45, 95, P), ("I125_95", 125, 95, P), ("I275_95", 275, 95, P),
    ("I45_235", 45, 235, P), ("I195_235", 195, 235, P), ("I90_130", 90, 130, P),
    ("I230_200", 230, 200, P),
    ("AS", 160, 95, P), ("AN", 160, 235, P), ("AW", 90, 165, P), ("AE", 230, 165, P),
    # roundabout ring
    ("RS", 160, 140, P), ("RE", 185, 165, P), ("RN", 160, 190, P), ("RW", 135, 165, P),
)

_ROADS = (
    # from, to, lanes per direction, rounded corners on the way
    # perimeter
    ("Pl95", "Pb45", 2, ((0, 0),)), ("Pb45", "Pb90", 2, ()), ("Pb90", "Pb125", 2, ()),
    ("Pb125", "Pb230", 2, ()), ("Pb230", "Pb275", 2, ()), ("Pb275", "Pr95", 2, ((320, 0),)),
    ("Pr95", "Pr200", 2, ()), ("Pr200", "Pr235", 2, ()), ("Pr235", "NE", 2, ()),
    ("NE", "Pt230", 2, ()), ("Pt230", "Pt195", 2, ()), ("Pt195", "Pt90", 2, ()),
    ("Pt90", "Pt45", 2, ()), ("Pt45", "Pl235", 2, ((0, 330),)),
    ("Pl235", "Pl130", 2, ()), ("Pl130", "Pl95", 2, ()),
    # south avenue y = 95 (3 lanes)
    ("Pl95", "I45_95", 3, ()), ("I45_95", "X90_95", 3, ()), ("X90_95", "I125_95", 3, ()),
    ("I125_95", "AS", 3, ()), ("AS", "X230_95", 3, ()), ("X230_95", "I275_95", 3, ()),
    ("I275_95", "Pr95", 3, ()),
    # north road y = 235
    ("Pl235", "I45_235", 2, ()), ("I45_235", "X90_235", 2, ()), ("X90_235", "AN", 2, ()),
    ("AN", "I195_235", 2, ()), ("I195_235", "X230_235", 2, ()), ("X230_235", "Pr235", 2, ()),
    # west road x = 90
    ("Pb90", "X90_95", 2, ()), ("X90_95", "I90_130", 2, ()), ("I90_130", "AW", 2, ()),
    ("AW", "X90_235", 2, ()), ("X90_235", "Pt90", 2, ()),
    # east road x = 230
    ("Pb230", "X230_95", 2, ()), ("X230_95", "AE", 2, ()), ("AE", "I230_200", 2, ()),
    ("I230_200", "X230_235", 2, ()), ("X230_235", "Pt230", 2, ()),
    # diagonal: fifth leg of X230_235
    ("X230_235", "NE", 2, ()),
    # roundabout approaches
    ("AS", "RS", 2, ()), ("AE", "RE", 2, ()), ("AN", "RN", 2, ()), ("AW", "RW", 2, ()),
    # side streets (1 lane)
    ("Pb45", "I45_95", 1, ()), ("Pb125", "I125_95", 1, ()), ("Pb275", "I275_95", 1, ()),
    ("Pl130", "I90_130", 1, ()), ("I230_200", "Pr200", 1, ()), ("I45_235", "Pt45", 1, ()),
    ("I195_235", "Pt195", 1, ()),
)

# counter-clockwise ring (right-hand traffic), 2 lanes, one-way arcs
_RING = (("RS", "RE", -90, 0), ("RE", "RN", 0, 90), ("RN", "RW", 90, 180),
         ("RW", "RS", 180, 270))



def _scaled(points):
    return tuple((x * SCALE, y * SCALE) for x, y in points)


SPEC = TownSpec(
    name="Town03",
    nodes=tuple(Node(i, x * SCALE, y * SCALE, t) for i, x, y, t in _NODES),
    roads=tuple(Road(a, b, lanes=n, corners=_scaled(c), radius=20.0 * SCALE)
                for a, b, n, c in _ROADS)
    + tuple(Road(a, b, lanes=2, oneway=True, radius=0.0,
                 corners=_scaled(arc_points(CENTER, RADIUS, s, e))) for a, b, s, e in _RING),
    roundabouts=(Roundabout(("RS", "RE", "RN", "RW")),),
    green_s=12,
)
