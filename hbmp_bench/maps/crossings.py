"""Pedestrian crossings an import keeps: only where roads meet.

netconvert guesses a crossing wherever sidewalks meet at a node (``--crossings.guess``), also at a node
that merely joins two pieces of one road: OpenDRIVE maps split roads at every change of lane layout
and join bends on as roads of their own (CARLA's Town01 road 11, a 15.8 m bend between roads 8 and 0).
To fit the crossing, netconvert widens such a node over the road, and the piece between two of them is
cut down to a stub (Town01's bend: 0.4 m left of its 20.4 m lane, drawn backwards), while the junction
lanes that replace it join the ends by a chord across the bend's inside. Crossings at such a
*continuation node* (one whose normal edges lead to at most two other nodes) are discarded
(:func:`discard_xml`, a netconvert ``--connection-files`` patch); the sidewalks and walking areas stay,
so pedestrians walk on and cross at the junctions.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from xml.sax.saxutils import quoteattr


def node_neighbours(root: ET.Element) -> dict[str, set[str]]:
    """For each node of a SUMO net (its parsed root element): the other nodes its normal edges lead to or come from."""
    out: dict[str, set[str]] = {}
    for edge in root.iter("edge"):
        if edge.get("function", "normal") != "normal":
            continue
        a, b = edge.get("from"), edge.get("to")
        if a is None or b is None or a == b:
            continue
        out.setdefault(a, set()).add(b)
        out.setdefault(b, set()).add(a)
    return out


def crossings_by_node(root: ET.Element) -> list[tuple[str, tuple[str, ...]]]:
    """Every crossing of a SUMO net (its parsed root element): (node id, crossed edge ids), sorted. A crossing's
    node is the junction whose internal lanes list the crossing's lane."""
    node_of_lane = {lane: j.get("id") for j in root.iter("junction") if j.get("type") != "internal"
                    for lane in (j.get("intLanes") or "").split()}
    out = []
    for edge in root.iter("edge"):
        if edge.get("function") != "crossing":
            continue
        crossed = tuple((edge.get("crossingEdges") or "").split())
        node = next((node_of_lane[lane.get("id")] for lane in edge.findall("lane") if lane.get("id") in node_of_lane),
                    None)
        if crossed and node is not None:
            out.append((node, crossed))
    return sorted(out)


def continuation_crossings(root: ET.Element) -> list[tuple[str, tuple[str, ...]]]:
    """The crossings of :func:`crossings_by_node` at continuation nodes (see the module docstring)."""
    neighbours = node_neighbours(root)
    return [(node, crossed) for node, crossed in crossings_by_node(root) if len(neighbours.get(node, ())) <= 2]


def discard_xml(crossings: list[tuple[str, tuple[str, ...]]]) -> str:
    """A netconvert ``--connection-files`` patch that discards each of ``crossings`` ((node, edges) pairs)."""
    rows = [f"    <crossing node={quoteattr(node)} edges={quoteattr(' '.join(edges))} discard=\"true\"/>"
            for node, edges in crossings]
    return "<connections>\n" + "\n".join(rows) + "\n</connections>\n"


__all__ = ["continuation_crossings", "crossings_by_node", "discard_xml", "node_neighbours"]
