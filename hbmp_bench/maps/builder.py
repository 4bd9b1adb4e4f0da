"""The one general builder: :class:`~hbmp_bench.maps.spec.TownSpec` -> plain XML -> net.

Plain XML files written per town: ``<Town>.nod.xml`` (nodes) and ``<Town>.edg.xml``
(edges and roundabouts). netconvert (from the eclipse-sumo wheel) turns them into
``<Town>.net.xml`` with right-hand traffic, 3.5 m lanes, sidewalks, guessed pedestrian
crossings, internal junction lanes and no U-turns. Traffic lights get netconvert's fixed-time
programs with the package's greens and all-red clearances; the yellows are then set per junction
from its approach speed (:mod:`hbmp_bench.maps.signals`).
"""

from __future__ import annotations

import re
import shutil
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

from ..errors import UnknownNameError
from .netconvert import run_netconvert
from .signals import ALL_RED_TIME_S, CROSSING_CLEARANCE_S, retime_yellows
from .spec import SIDEWALK_WIDTH, Road, TownSpec, rounded_polyline
from .towns import TOWNS, town_spec

#: netconvert options shared by every generated town (see the SUMO netconvert docs); the
#: green of the lights' main phases is the town's (``--tls.green.time``, :attr:`TownSpec.green_s`).
NETCONVERT_OPTIONS: tuple[str, ...] = (
    "--default.lanewidth", "3.5",          # m
    "--default.sidewalk-width", str(SIDEWALK_WIDTH),  # m
    "--default.junctions.radius", "6",     # m, corner radius of junction shapes
    # pedestrians waiting at a crossing stand on the kerb line across its width: with 4 m crossings and
    # 5-point junction lanes (whose chords cut towards the kerb) right turns passed into them
    # (RoadNetwork.crossing_clearance: -0.35 to -1.23 m); smooth lanes and 2 m crossings leave room
    "--junctions.internal-link-detail", "20",  # points per junction lane curve (default 5)
    "--default.crossing-width", "2",           # m (default 4)
    "--crossings.guess", "true",
    "--no-turnarounds", "true",
    "--junctions.join", "false",
    "--geometry.remove", "false",
    "--roundabouts.guess", "false",    # roundabouts are declared in the spec
    "--tls.guess", "false",
    "--tls.allred.time", str(ALL_RED_TIME_S),      # s, after every yellow
    "--tls.left-green.time", "0",                  # no protected left phases: lefts yield
    "--tls.crossing-clearance.time", str(CROSSING_CLEARANCE_S),  # s
    "--offset.disable-normalization", "true",
    "--output.street-names", "false",
    "--xml-validation", "never",
    "--no-warnings", "true",
)


def _fmt(v: float) -> str:
    return f"{v:.2f}"


def _shape(points: list[tuple[float, ...]]) -> str:
    return " ".join(",".join(_fmt(c) for c in p) for p in points)


def _road_points(spec: TownSpec, road: Road) -> list[tuple[float, ...]]:
    """The road's shape (m): (x, y), or (x, y, z) for a bridge (``road.elevation``)."""
    a, b = spec.node(road.a), spec.node(road.b)
    pts = rounded_polyline([(a.x, a.y), *road.corners, (b.x, b.y)], road.radius)
    if not road.elevation:
        return pts
    return [(*p, 0.0 if k in (0, len(pts) - 1) else road.elevation) for k, p in enumerate(pts)]


def _edge_element(parent: ET.Element, edge_id: str, frm: str, to: str, road: Road,
                  points: list[tuple[float, float]]) -> None:
    attrs = {
        "id": edge_id,
        "from": frm,
        "to": to,
        "numLanes": str(road.lanes),
        "speed": _fmt(road.speed),
        "spreadType": "center" if road.oneway else "right",
    }
    if len(points) > 2:
        attrs["shape"] = _shape(points)
    if road.sidewalk:
        attrs["sidewalkWidth"] = _fmt(SIDEWALK_WIDTH)
    else:
        attrs["disallow"] = "pedestrian"
    ET.SubElement(parent, "edge", attrs)


def write_plain_xml(spec: TownSpec, out_dir: Path) -> tuple[Path, Path]:
    """Write ``<name>.nod.xml`` and ``<name>.edg.xml`` for ``spec`` into ``out_dir``.

    Returns the paths (nodes, edges).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)

    nodes = ET.Element("nodes")
    for n in spec.nodes:
        ET.SubElement(nodes, "node", {"id": n.id, "x": _fmt(n.x), "y": _fmt(n.y),
                                      "type": n.type})

    edges = ET.Element("edges")
    seen: set[str] = set()
    for road in spec.roads:
        pts = _road_points(spec, road)
        fwd = road.edge_id
        ids = [fwd] if road.oneway else [fwd, f"-{fwd}"]
        for eid in ids:
            if eid in seen:
                raise ValueError(f"{spec.name}: duplicate edge id {eid!r}")
            seen.add(eid)
        _edge_element(edges, fwd, road.a, road.b, road, pts)
        if not road.oneway:
            _edge_element(edges, f"-{fwd}", road.b, road.a, road, pts[::-1])
    for ring in spec.roundabouts:
        ring_edges = []
        for i, a in enumerate(ring.nodes):
            b = ring.nodes[(i + 1) % len(ring.nodes)]
            match = [r for r in spec.roads if r.a == a and r.b == b and r.oneway]
            if len(match) != 1:
                raise ValueError(f"{spec.name}: roundabout needs one one-way road {a}->{b}")
            ring_edges.append(match[0].edge_id)
        ET.SubElement(edges, "roundabout", {"nodes": " ".join(ring.nodes),
                                            "edges": " ".join(ring_edges)})

    nod_path = out_dir / f"{spec.name}.nod.xml"
    edg_path = out_dir / f"{spec.name}.edg.xml"
    for root, path in ((nodes, nod_path), (edges, edg_path)):
        ET.indent(root)
        ET.ElementTree(root).write(path, encoding="UTF-8", xml_declaration=True)
    return nod_path, edg_path


_HEADER = re.compile(r"<!-- generated on .*?-->\s*", re.S)


def _strip_header(net_path: Path) -> None:
    """Drop netconvert's header comment (date and option list) for deterministic files."""
    text = net_path.read_text(encoding="utf-8")
    net_path.write_text(_HEADER.sub("", text, count=1), encoding="utf-8")


def build_spec(spec: TownSpec, out_dir: Path, keep_plain: bool = False) -> Path:
    """Build ``<out_dir>/<name>.net.xml`` from ``spec``; returns its path.

    The plain XML is written into a temporary directory (copied to ``out_dir`` too when
    ``keep_plain``); netconvert runs there with relative file names.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="hbmp_map_") as tmp:
        tmp_dir = Path(tmp)
        nod, edg = write_plain_xml(spec, tmp_dir)
        net_name = f"{spec.name}.net.xml"
        run_netconvert(["--node-files", nod.name, "--edge-files", edg.name, *NETCONVERT_OPTIONS,
                        "--tls.green.time", str(spec.green_s), "--output-file", net_name], cwd=tmp_dir)
        _strip_header(tmp_dir / net_name)
        retime_yellows(tmp_dir / net_name)
        if keep_plain:
            for p in (nod, edg):
                shutil.copy2(p, out_dir / p.name)
        target = out_dir / net_name
        shutil.move(str(tmp_dir / net_name), target)
    return target


def build_town(name: str, out_dir: Path) -> Path:
    """Build built-in town ``name`` into ``<out_dir>/<name>.net.xml`` (the generator that
    made the shipped file); returns the path. UnknownNameError for other names."""
    if name not in TOWNS:
        raise UnknownNameError("town", name, TOWNS)
    return build_spec(town_spec(name), Path(out_dir))
