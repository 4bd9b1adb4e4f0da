"""Summary statistics of a SUMO ``.net.xml`` (read directly with ElementTree: fast).

Definitions (units: m):

* drivable edge: a non-internal edge (no ``function`` attribute, or ``normal``) with at
  least one car lane: a lane that allows ``passenger`` and is not of a lane type the benchmark closes
  to cars (:func:`~hbmp_bench.maps.lanetypes.is_car_lane`: a raw CARLA net's parking and
  bidirectional lanes count as an import of it leaves them); its vehicle lanes are those lanes.
* edge length: mean length of the edge's vehicle lanes, m.
* directed road length: sum of the lengths of all drivable edges (each direction counts);
  driving lane length: the sum over their vehicle lanes; ``lanes_per_edge_mean``: their ratio, the
  mean number of vehicle lanes per edge weighted by length (an edge split into pieces counts as
  one).
* walkable edge: a normal edge with a lane that allows ``pedestrian``.
* junctions: ``traffic_light*`` nodes are TLS junctions; ``priority``, ``priority_stop``,
  ``right_before_left``, ``left_before_right``, ``allway_stop`` and ``zipper`` nodes are
  priority junctions; dead ends, internal and other nodes are no junctions.
* extent: width and height of the net's ``convBoundary``, m.
* signal timing (s): ``tls_yellow_s``, ``tls_all_red_s`` (phase durations), ``tls_green_s`` (a
  vehicle link's green per cycle), ``tls_red_s`` (a vehicle link's longest red) and
  ``tls_cycle_s``, each [min, max] over the net's lights
  (:func:`hbmp_bench.maps.signals.signal_stats`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

from .lanetypes import allows, is_car_lane
from .signals import signal_stats

TLS_TYPES = frozenset({"traffic_light", "traffic_light_unregulated",
                       "traffic_light_right_on_red"})
PRIORITY_TYPES = frozenset({"priority", "priority_stop", "right_before_left",
                            "left_before_right", "allway_stop", "zipper"})


def _is_sidewalk(lane: ET.Element) -> bool:
    return lane.get("allow", "").split() == ["pedestrian"]


def net_stats(path: str | Path) -> dict:
    """Statistics of the net file at ``path`` (see the module docstring).

    Returns a dict with ``directed_road_length_m`` and ``driving_lane_length_m`` (float, m),
    ``drivable_edges``,
    ``lanes_per_edge`` ({lane count as str: number of drivable edges}), ``lanes_per_edge_mean``,
    ``tls_junctions``, ``priority_junctions``, ``roundabouts``, ``extent_m``
    ([width, height], m), ``has_sidewalks`` (bool), ``walkable_edges``, ``crossings`` (int) and the signal
    timing ``tls_*_s`` ([min, max], s).
    """
    root = ET.parse(path).getroot()
    edges = _edge_stats(root)
    length, lane_length, lanes_per_edge = edges.pop("length"), edges.pop("lane_length"), edges.pop("lanes_per_edge")
    types = Counter(j.get("type") for j in root.iter("junction"))
    return {
        "directed_road_length_m": round(length, 2),
        "driving_lane_length_m": round(lane_length, 2),
        "drivable_edges": edges["drivable"],
        "lanes_per_edge": {str(k): lanes_per_edge[k] for k in sorted(lanes_per_edge)},
        "lanes_per_edge_mean": round(lane_length / length, 3) if length > 0 else 0.0,
        "tls_junctions": sum(types[t] for t in TLS_TYPES),
        "priority_junctions": sum(types[t] for t in PRIORITY_TYPES),
        "roundabouts": len(root.findall("roundabout")),
        "extent_m": _extent(root),
        "has_sidewalks": edges["sidewalks"],
        "walkable_edges": edges["walkable"],
        "crossings": edges["crossings"],
        **{f"tls_{key}": value for key, value in signal_stats(path).items()},
    }


def _edge_stats(root) -> dict:
    """Over the normal edges of a net's XML root: directed road length and driving lane length [m], drivable
    edges, lanes per drivable edge (a Counter), walkable edges, whether any has a sidewalk; and the crossings."""
    out = {"length": 0.0, "lane_length": 0.0, "drivable": 0, "lanes_per_edge": Counter(), "walkable": 0,
           "sidewalks": False, "crossings": 0}
    for edge in root.iter("edge"):
        function = edge.get("function", "normal")
        out["crossings"] += function == "crossing"
        if function != "normal":
            continue
        lanes = edge.findall("lane")
        out["sidewalks"] = out["sidewalks"] or any(_is_sidewalk(ln) for ln in lanes)
        out["walkable"] += any(allows(ln, "pedestrian") for ln in lanes)
        vehicle = [ln for ln in lanes if is_car_lane(ln, edge)]
        if not vehicle:
            continue
        out["drivable"] += 1
        out["lanes_per_edge"][len(vehicle)] += 1
        out["length"] += sum(float(ln.get("length")) for ln in vehicle) / len(vehicle)
        out["lane_length"] += sum(float(ln.get("length")) for ln in vehicle)
    return out


def _extent(root) -> list[float]:
    """[width, height] [m] of a net's ``convBoundary`` ([0, 0] without one)."""
    loc = root.find("location")
    if loc is not None and loc.get("convBoundary"):
        x0, y0, x1, y1 = (float(v) for v in loc.get("convBoundary").split(","))
        return [round(x1 - x0, 2), round(y1 - y0, 2)]
    return [0.0, 0.0]


def _cell(value) -> str:
    if isinstance(value, dict):
        return " ".join(f"{k}:{v}" for k, v in value.items()) or "-"
    if isinstance(value, (list, tuple)):
        return "..".join(f"{v:g}" for v in value) if len(value) == 2 and value[0] != value[1] else \
            (f"{value[0]:g}" if value else "-")
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def format_stats(stats: dict[str, dict]) -> str:
    """Side-by-side text table of :func:`net_stats` dicts keyed by map name: one row per figure, one
    column per map; a number of the second and later maps also shows its difference from the first's
    (``+1.2%``). An imported map's provenance (``import``) shows as its source file and light timing."""
    names = list(stats)
    keys = list(dict.fromkeys(k for s in stats.values() for k in s))
    rows = [["", *names]]
    for key in keys:
        row = [key]
        first = stats[names[0]].get(key)
        for i, name in enumerate(names):
            value = stats[name].get(key)
            if key == "import":
                cell = f"{value.get('source', '?')}, lights {value.get('lights', '?')}" if value else "-"
            elif value is None:
                cell = "-"
            elif key == "extent_m":
                cell = " x ".join(f"{v:g}" for v in value)
            else:
                cell = _cell(value)
                if i and isinstance(value, (int, float)) and not isinstance(value, bool) and \
                        isinstance(first, (int, float)) and not isinstance(first, bool) and first:
                    cell += f" ({100.0 * (value - first) / first:+.1f}%)"
            row.append(cell)
        rows.append(row)
    widths = [max(len(r[c]) for r in rows) for c in range(len(rows[0]))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(r, widths)).rstrip() for r in rows)
