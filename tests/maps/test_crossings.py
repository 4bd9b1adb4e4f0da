"""Crossings an import keeps: at nodes where roads meet, not where one road merely continues."""

from __future__ import annotations

import xml.etree.ElementTree as ET

from hbmp_bench.maps import import_map, map_info, net_path
from hbmp_bench.maps.crossings import continuation_crossings, crossings_by_node, node_neighbours
from hbmp_bench.maps.netconvert import run_netconvert
from hbmp_bench.scenarios import road_network

NODES = """<nodes>
    <node id="A" x="0" y="0"/>
    <node id="B" x="100" y="0"/>
    <node id="C" x="140" y="40"/>
    <node id="D" x="240" y="40"/>
    <node id="E" x="140" y="140"/>
</nodes>
"""
"""A road A-B-C bending at B (B only joins two pieces of it), then a T junction at C (to D and E)."""

EDGES = "<edges>\n" + "".join(
    f'    <edge id="{a}{b}" from="{a}" to="{b}" numLanes="1" speed="13.89" sidewalkWidth="2"/>\n'
    f'    <edge id="{b}{a}" from="{b}" to="{a}" numLanes="1" speed="13.89" sidewalkWidth="2"/>\n'
    for a, b in (("A", "B"), ("B", "C"), ("C", "D"), ("C", "E"))) + "</edges>\n"


def _guessed_net(tmp_path):
    (tmp_path / "n.nod.xml").write_text(NODES)
    (tmp_path / "e.edg.xml").write_text(EDGES)
    run_netconvert(["-n", "n.nod.xml", "-e", "e.edg.xml", "--crossings.guess", "true", "--no-warnings", "true",
                    "-o", "guessed.net.xml"], cwd=tmp_path)
    return tmp_path / "guessed.net.xml"


def test_a_guessed_crossing_at_a_bend_is_found_and_the_junctions_are_kept(tmp_path):
    root = ET.parse(_guessed_net(tmp_path)).getroot()
    assert {len(v) for k, v in node_neighbours(root).items() if k in "BC"} == {2, 3}
    nodes = {node for node, _ in crossings_by_node(root)}
    assert {"B", "C"} <= nodes  # netconvert guesses both
    assert {node for node, _ in continuation_crossings(root)} == {"B"}


def test_import_discards_crossings_at_a_bend_only(tmp_path):
    src = _guessed_net(tmp_path)
    at_bend = [c for c in crossings_by_node(ET.parse(src).getroot()) if c[0] == "B"]
    import_map(src, "bend")
    root = ET.parse(net_path("bend")).getroot()
    assert {node for node, _ in crossings_by_node(root)} == {"C"}
    assert map_info("bend")["crossings_discarded"] == len(at_bend) > 0
    assert "BC_1" in road_network("bend").lanes  # the road itself is untouched
