"""Town05: a square grid of multi-lane roads, 6 x 5 nodes over 470 m x 400 m.

Interior 4-leg cross junctions are signalised, as are the two ends of the 3-lane
avenue; the other boundary T-junctions and the four corners are priority nodes.
The avenue (row y = 200 m) and two boulevards (columns x = 188 m and x = 376 m) have
3 lanes per direction, every other road 2. All roads 13.89 m/s.
"""

from ..spec import Node, Road, TownSpec

XS = (0.0, 94.0, 188.0, 282.0, 376.0, 470.0)   # column positions, m
YS = (0.0, 100.0, 200.0, 300.0, 400.0)        # row positions, m
WIDE_ROWS = (2,)       # row indices with 3 lanes per direction
WIDE_COLS = (2, 4)     # column indices with 3 lanes per direction


def _nid(i: int, j: int) -> str:
    return f"C{i}R{j}"


def _type(i: int, j: int) -> str:
    interior = 0 < i < len(XS) - 1 and 0 < j < len(YS) - 1
    avenue_end = j in WIDE_ROWS and i in (0, len(XS) - 1)
    return "traffic_light" if interior or avenue_end else "priority"


_NODES = tuple(Node(_nid(i, j), x, y, _type(i, j))
               for j, y in enumerate(YS) for i, x in enumerate(XS))

_ROADS = (
    tuple(Road(_nid(i, j), _nid(i + 1, j), lanes=3 if j in WIDE_ROWS else 2)
          for j in range(len(YS)) for i in range(len(XS) - 1))
    + tuple(Road(_nid(i, j), _nid(i, j + 1), lanes=3 if i in WIDE_COLS else 2)
            for i in range(len(XS)) for j in range(len(YS) - 1))
)

SPEC = TownSpec(name="Town05", nodes=_NODES, roads=_ROADS)
