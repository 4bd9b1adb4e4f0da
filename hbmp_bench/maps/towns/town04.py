"""Town04: a 4-lane-per-direction highway loop around a small one-lane town.

The highway is two one-way carriageways (4 lanes each, 25 m/s) on a rectangle of
``W`` x ``H`` m with rounded corners: the outer one runs counter-clockwise, the inner
one (``INSET`` m inside) clockwise, so both keep the median on their left. Each side
has an interchange: a signalised ramp terminal ``R`` (``RAMP_T`` m inside the outer
carriageway) with an exit and an entry ramp (1 lane, 16.67 m/s) to each carriageway;
ramps of the outer carriageway bridge over the inner one (``BRIDGE_Z`` m up, no junction
where they cross: actors on the two levels never meet). A connector road links each terminal with the town, a 4 x 3 grid of one-lane
streets (80 m blocks, signalised junctions, rounded outer corners); the southern
connector has two lanes. Besides the ramp junctions each carriageway is split once per
side (nodes ``K``) before the corner.
"""

from __future__ import annotations

from ..spec import HIGHWAY_SPEED, RAMP_SPEED, Node, Point, Road, TownSpec

T, P = "traffic_light", "priority"
W, H = 760.0, 680.0      # outer carriageway rectangle, m
INSET = 24.0             # inner carriageway inset, m
RAMP_T = 60.0            # ramp terminal distance inside the outer carriageway, m
BRIDGE_Z = 6.0           # height of the bridging ramps over the inner carriageway, m
HW_RADIUS = 70.0         # outer corner radius, m (inner: HW_RADIUS - INSET)
CX, CY = W / 2, H / 2    # town centre, m
BLOCK = 80.0             # town block size, m
TOWN_X = (CX - 1.5 * BLOCK, CX - 0.5 * BLOCK, CX + 0.5 * BLOCK, CX + 1.5 * BLOCK)
TOWN_Y = (CY - BLOCK, CY, CY + BLOCK)

# Interchange frames, in the order the outer (counter-clockwise) carriageway meets
# them: side name, origin on the outer carriageway (m), unit vector u along the outer
# driving direction, unit vector v pointing inside.
_SIDES = (
    ("S", (TOWN_X[1], 0.0), (1.0, 0.0), (0.0, 1.0)),
    ("E", (W, CY), (0.0, 1.0), (-1.0, 0.0)),
    ("N", (TOWN_X[2], H), (-1.0, 0.0), (0.0, -1.0)),
    ("W", (0.0, CY), (0.0, -1.0), (1.0, 0.0)),
)
# Outer carriageway corners after each side (counter-clockwise), inner ones before it.
_OUTER_CORNERS = ((W, 0.0), (W, H), (0.0, H), (0.0, 0.0))
_INNER_CORNERS = ((INSET, INSET), (W - INSET, INSET), (W - INSET, H - INSET),
                  (INSET, H - INSET))

# Interchange geometry in local (u, v) coordinates, m. Outer carriageway at v = 0
# (driving +u), inner at v = INSET (driving -u), terminal R at (0, RAMP_T).
_STATIONS_OUTER = (("Dout", -130.0), ("Mout", 130.0), ("Kout", 220.0))   # in driving order
_STATIONS_INNER = (("Din", 45.0), ("Min", -45.0), ("Kin", -220.0))
_RAMPS = (
    # from, to, shape points (u, v) between them, elevation of those points [m] (the outer
    # carriageway's ramps bridge over the inner one)
    ("Dout", "R", ((-100.0, -12.0), (-60.0, -12.0), (-60.0, RAMP_T)), BRIDGE_Z),
    ("R", "Mout", ((60.0, RAMP_T), (60.0, -12.0), (100.0, -12.0)), BRIDGE_Z),
    ("Din", "R", ((20.0, 40.0),), 0.0),
    ("R", "Min", ((-20.0, 40.0),), 0.0),
)
# Town junction each terminal's connector leads to, and the connector's lane count.
_CONNECT = {"S": ("T1_0", 2), "E": ("T3_1", 1), "N": ("T2_2", 1), "W": ("T0_1", 1)}


def _at(side: tuple, u: float, v: float) -> Point:
    _name, (ox, oy), (ux, uy), (vx, vy) = side
    return (ox + u * ux + v * vx, oy + u * uy + v * vy)


def _highway() -> tuple[list[Node], list[Road]]:
    nodes: list[Node] = []
    roads: list[Road] = []
    for ring, stations, v, corners, order in (
        ("out", _STATIONS_OUTER, 0.0, _OUTER_CORNERS, (0, 1, 2, 3)),
        ("in", _STATIONS_INNER, INSET, _INNER_CORNERS, (0, 3, 2, 1)),
    ):
        seq: list[str] = []
        for k in order:
            side = _SIDES[k]
            for name, u in stations:
                nid = f"{name}_{side[0]}"
                x, y = _at(side, u, v)
                nodes.append(Node(nid, x, y, P))
                seq.append(nid)
        radius = HW_RADIUS if ring == "out" else HW_RADIUS - INSET
        per_side = len(stations)
        for i, a in enumerate(seq):
            b = seq[(i + 1) % len(seq)]
            wraps = (i + 1) % per_side == 0
            corner = corners[order[i // per_side]] if wraps else None
            roads.append(Road(a, b, lanes=4, speed=HIGHWAY_SPEED, oneway=True,
                              sidewalk=False, corners=(corner,) if corner else (),
                              radius=radius))
    return nodes, roads


def _interchanges() -> tuple[list[Node], list[Road]]:
    nodes: list[Node] = []
    roads: list[Road] = []
    for side in _SIDES:
        s = side[0]
        r = f"R_{s}"
        nodes.append(Node(r, *_at(side, 0.0, RAMP_T), T))
        for a, b, pts, z in _RAMPS:
            roads.append(Road(f"{a}_{s}" if a != "R" else r, f"{b}_{s}" if b != "R" else r,
                              lanes=1, speed=RAMP_SPEED, oneway=True, sidewalk=False,
                              corners=tuple(_at(side, u, v) for u, v in pts), radius=15.0, elevation=z))
        town_node, lanes = _CONNECT[s]
        roads.append(Road(r, town_node, lanes=lanes))
    return nodes, roads


def _town() -> tuple[list[Node], list[Road]]:
    nx, ny = len(TOWN_X), len(TOWN_Y)
    corners = {(0, 0), (nx - 1, 0), (0, ny - 1), (nx - 1, ny - 1)}
    nodes = [Node(f"T{i}_{j}", x, y, T) for j, y in enumerate(TOWN_Y)
             for i, x in enumerate(TOWN_X) if (i, j) not in corners]
    roads = [Road(f"T{i}_{j}", f"T{i + 1}_{j}") for j in range(ny) for i in range(nx - 1)
             if (i, j) not in corners and (i + 1, j) not in corners]
    roads += [Road(f"T{i}_{j}", f"T{i}_{j + 1}") for i in range(nx) for j in range(ny - 1)
              if (i, j) not in corners and (i, j + 1) not in corners]
    # rounded outer corners: one road around each corner (radius 15 m)
    for (ci, cj), (a, b) in {
        (0, 0): ("T0_1", "T1_0"), (nx - 1, 0): ("T2_0", f"T{nx - 1}_1"),
        (nx - 1, ny - 1): (f"T{nx - 1}_1", f"T{nx - 2}_{ny - 1}"),
        (0, ny - 1): ("T1_2", "T0_1"),
    }.items():
        roads.append(Road(a, b, corners=((TOWN_X[ci], TOWN_Y[cj]),), radius=15.0))
    return nodes, roads


def _spec() -> TownSpec:
    nodes: list[Node] = []
    roads: list[Road] = []
    for part in (_highway, _interchanges, _town):
        n, r = part()
        nodes += n
        roads += r
    return TownSpec(name="Town04", nodes=tuple(nodes), roads=tuple(roads))


SPEC = _spec()
