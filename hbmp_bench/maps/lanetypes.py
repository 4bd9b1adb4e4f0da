"""OpenDRIVE lane types and what each may carry in the benchmark's SUMO nets.

Only the car lane types carry the ``passenger`` class: the ego's routes, starts and goals, the
background cars and the lane graph (:class:`~hbmp_bench.maps.roadnet.RoadNetwork`: a drivable
lane allows ``passenger``) use nothing else. Sidewalks carry pedestrians, bike lanes bicycles; a
parking, shoulder, bidirectional, median or any other lane stays in the net, drawn where the map
has it, closed to every class (``disallow="all"``): a car there is off the road.

OpenDRIVE imports get these permissions from netconvert's type map (:func:`typemap_xml`); a SUMO
net made by netconvert's default map (CARLA's own ``.net.xml``: parking and bidirectional lanes at
5 km/h open to cars) gets them from a patch of its lanes (:func:`lane_patches`). A lane's type is
its ``type`` attribute, else its place in its edge's composite type (``"parking|driving"``: index
0 parking, index 1 driving) where that names every lane, else ``sidewalk`` for a lane of pedestrians
only (netconvert's guessed sidewalks), else its edge's type.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from xml.sax.saxutils import quoteattr


CAR_CLASSES_DISALLOWED = ("pedestrian rail rail_urban rail_electric rail_fast tram drone aircraft scooter "
                          "container wheelchair subway cable_car ship")
"""What a car lane disallows (netconvert's own OpenDRIVE map): everything but road vehicles."""

CAR_LANE_TYPES: tuple[str, ...] = ("driving", "entry", "exit", "onRamp", "offRamp", "connectingRamp",
                                   "mwyEntry", "mwyExit")
"""OpenDRIVE lane types a car drives in."""

WALK_LANE_TYPES: tuple[str, ...] = ("sidewalk", "walking")
"""OpenDRIVE lane types of pedestrians (``allow="pedestrian"``)."""

OTHER_LANE_PERMISSIONS: dict[str, str] = {
    "biking": "bicycle",
    "bus": "bus",
    "taxi": "taxi",
    "HOV": "hov",
    "tram": "tram",
    "rail": "rail rail_urban rail_electric rail_fast",
}
"""OpenDRIVE lane types kept for another class (the ``allow`` list)."""

CLOSED_LANE_TYPES: tuple[str, ...] = ("parking", "bidirectional", "shoulder", "stop", "restricted", "border",
                                      "median", "curb", "none", "roadWorks", "special1", "special2", "special3")
"""OpenDRIVE lane types kept in the net and closed to every class (``disallow="all"``)."""

_DEFAULT_SPEED = {"sidewalk": 2.78, "walking": 2.78, "biking": 5.56}


def allows(lane: ET.Element, vclass: str) -> bool:
    """Whether a ``<lane>`` element's allow/disallow attributes admit ``vclass``."""
    allow = lane.get("allow")
    if allow is not None:
        classes = allow.split()
        return vclass in classes or "all" in classes
    disallow = lane.get("disallow")
    if disallow is not None:
        classes = disallow.split()
        return vclass not in classes and "all" not in classes
    return True


def permissions(lane_type: str) -> dict[str, str] | None:
    """SUMO ``allow``/``disallow`` attributes of an OpenDRIVE lane type; None for a type this module
    does not know (an OSM or user type: left as its net has it)."""
    if lane_type in CAR_LANE_TYPES:
        return {"disallow": CAR_CLASSES_DISALLOWED}
    if lane_type in WALK_LANE_TYPES:
        return {"allow": "pedestrian"}
    if lane_type in OTHER_LANE_PERMISSIONS:
        return {"allow": OTHER_LANE_PERMISSIONS[lane_type]}
    if lane_type in CLOSED_LANE_TYPES:
        return {"disallow": "all"}
    return None


def typemap_xml() -> str:
    """netconvert type map (``--type-files``) for OpenDRIVE imports: every known lane type with
    :func:`permissions`, none discarded (with ``--opendrive.import-all-lanes`` they keep their place
    and width, so sidewalks stay beside the road)."""
    rows = []
    for lane_type in (*CAR_LANE_TYPES, *WALK_LANE_TYPES, *OTHER_LANE_PERMISSIONS, *CLOSED_LANE_TYPES):
        car = lane_type in CAR_LANE_TYPES
        speed = 13.89 if car else _DEFAULT_SPEED.get(lane_type, 1.39)
        width = 3.65 if car else 2.0
        attrs = " ".join(f"{k}={quoteattr(v)}" for k, v in permissions(lane_type).items())
        rows.append(f'    <type id="{lane_type}" priority="{1 if car else 0}" speed="{speed}" width="{width}" {attrs}/>')
    return "<types>\n" + "\n".join(rows) + "\n</types>\n"


def lane_type(lane: ET.Element, edge: ET.Element) -> str:
    """OpenDRIVE type of a ``<lane>`` of ``<edge>`` ("" where the net does not say)."""
    own = lane.get("type")
    if own:
        return own
    if (lane.get("allow") or "").split() == ["pedestrian"]:
        return "sidewalk"  # a guessed sidewalk carries its edge's type
    parts = (edge.get("type") or "").split("|")
    if len(parts) > 1:  # one part per lane, as netconvert wrote them (not after a sidewalk was added)
        return parts[int(lane.get("index", "0"))] if len(parts) == len(edge.findall("lane")) else ""
    return parts[0]


def closed_to_cars(kind: str) -> bool:
    """Whether the benchmark closes lanes of OpenDRIVE type ``kind`` to cars (a known type that is no
    car lane; an unknown type is left as its net has it)."""
    return permissions(kind) is not None and kind not in CAR_LANE_TYPES


def is_car_lane(lane: ET.Element, edge: ET.Element) -> bool:
    """Whether a ``<lane>`` of ``<edge>`` carries cars in the benchmark: it allows ``passenger`` and its
    type is not one the benchmark closes (a SUMO net made by netconvert's default type map, as CARLA's
    own, leaves parking and bidirectional lanes open to cars: an import closes them, :func:`lane_patches`)."""
    return allows(lane, "passenger") and not closed_to_cars(lane_type(lane, edge))


def lane_patches(root: ET.Element) -> list[tuple[str, int, str, dict[str, str]]]:
    """The lanes of a net's normal edges that are open to cars although their type is not a car
    lane: (edge id, lane index, lane type, the type's :func:`permissions`)."""
    out = []
    for edge in root.iter("edge"):
        if edge.get("function", "normal") != "normal":
            continue
        for lane in edge.findall("lane"):
            kind = lane_type(lane, edge)
            if closed_to_cars(kind) and allows(lane, "passenger"):
                out.append((edge.get("id"), int(lane.get("index", "0")), kind, permissions(kind)))
    return out


def patch_xml(patches: list[tuple[str, int, str, dict[str, str]]]) -> str:
    """A netconvert ``--edge-files`` patch giving each lane of ``patches`` its permissions."""
    by_edge: dict[str, list[str]] = {}
    for edge, index, _kind, attrs in patches:
        text = " ".join(f"{k}={quoteattr(v)}" for k, v in attrs.items())
        by_edge.setdefault(edge, []).append(f'        <lane index="{index}" {text}/>')
    rows = [f"    <edge id={quoteattr(e)}>\n" + "\n".join(lanes) + "\n    </edge>" for e, lanes in by_edge.items()]
    return "<edges>\n" + "\n".join(rows) + "\n</edges>\n"
