"""Lane types on import: only driving lanes carry cars, in OpenDRIVE and in SUMO nets.

Small crafted OpenDRIVE roads hold one lane of each type beside a driving lane per direction; the
same roads converted by netconvert's default type map (how CARLA made its own SUMO nets: parking and
bidirectional lanes open to cars) are imported as ``.net.xml``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from hbmp_bench.maps import import_map, map_info, map_stats, net_path, net_stats
from hbmp_bench.maps.lanetypes import CAR_LANE_TYPES, allows, lane_type
from hbmp_bench.maps.netconvert import run_netconvert
from hbmp_bench.maps.roadnet import RoadNetwork

OTHER_TYPES = ("parking", "shoulder", "sidewalk", "biking", "bidirectional", "stop", "restricted", "median",
               "border", "curb", "none")


def _lane(lane_id: int, kind: str, width: float = 3.5) -> str:
    return (f'<lane id="{lane_id}" type="{kind}" level="false"><link/>'
            f'<width sOffset="0.0" a="{width}" b="0" c="0" d="0"/></lane>')


def crafted_xodr(right: list[str], left: list[str], length: float = 120.0) -> str:
    """One straight road [m] with the given lane types, innermost first, on each side."""
    rights = "".join(_lane(-(k + 1), t, 3.5 if t in CAR_LANE_TYPES else 2.0) for k, t in enumerate(right))
    lefts = "".join(_lane(k + 1, t, 3.5 if t in CAR_LANE_TYPES else 2.0) for k, t in enumerate(left))
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<OpenDRIVE>
  <header revMajor="1" revMinor="4" name="crafted" version="1.00"/>
  <road name="r" length="{length}" id="1" junction="-1">
    <link/>
    <planView><geometry s="0.0" x="0.0" y="0.0" hdg="0.0" length="{length}"><line/></geometry></planView>
    <lanes><laneSection s="0.0">
      <left>{lefts}</left>
      <center><lane id="0" type="none" level="false"><link/></lane></center>
      <right>{rights}</right>
    </laneSection></lanes>
  </road>
</OpenDRIVE>
"""


def _lanes_by_type(path) -> list[tuple[str, ET.Element]]:
    root = ET.parse(path).getroot()
    return [(lane_type(ln, e), ln) for e in root.iter("edge") if e.get("function", "normal") == "normal"
            for ln in e.findall("lane")]


def _check_permissions(path, types: tuple[str, ...]) -> None:
    lanes = _lanes_by_type(path)
    seen = {kind for kind, _ in lanes}
    assert set(types) <= seen, f"lane types lost on import: {set(types) - seen}"
    for kind, lane in lanes:
        if kind in CAR_LANE_TYPES:
            assert allows(lane, "passenger") and not allows(lane, "pedestrian"), lane.attrib
        elif kind in ("sidewalk", "walking"):
            assert allows(lane, "pedestrian") and not allows(lane, "passenger"), lane.attrib
        elif kind:
            assert not allows(lane, "passenger"), (kind, lane.attrib)
            assert not allows(lane, "pedestrian"), (kind, lane.attrib)
    net = RoadNetwork.from_sumo(path)
    types_by_id = {ln.get("id"): kind for kind, ln in lanes}
    assert net.lanes and all(types_by_id[lane] in CAR_LANE_TYPES for lane in net.lanes)


@pytest.mark.parametrize("kind", OTHER_TYPES)
def test_each_lane_type_of_an_xodr_is_kept_closed_to_cars(tmp_path, kind):
    src = tmp_path / f"{kind}.xodr"
    src.write_text(crafted_xodr(["driving", kind], ["driving", kind]), encoding="utf-8")
    import_map(src, f"road_{kind}")
    _check_permissions(net_path(f"road_{kind}"), (kind, "driving"))
    stats = map_stats(f"road_{kind}")
    assert stats["lanes_per_edge"] == {"1": 2}
    assert stats["directed_road_length_m"] == pytest.approx(240.0, abs=1.0)


def test_every_lane_type_on_one_road(tmp_path):
    right = ["driving", "biking", "parking", "shoulder", "sidewalk"]
    left = ["driving", "bidirectional", "stop", "border", "sidewalk"]
    src = tmp_path / "all.xodr"
    src.write_text(crafted_xodr(right, left), encoding="utf-8")
    import_map(src, "all_types")
    path = net_path("all_types")
    _check_permissions(path, tuple(set(right + left)))
    stats = map_stats("all_types")
    assert stats["lanes_per_edge"] == {"1": 2} and stats["walkable_edges"] == 2
    assert stats["import"]["sidewalks_guessed"] is False  # the map's own sidewalks
    bike = [ln for kind, ln in _lanes_by_type(path) if kind == "biking"]
    assert bike and all(ln.get("allow") == "bicycle" for ln in bike)


def test_multi_lane_driving_roads_keep_every_driving_lane(tmp_path):
    src = tmp_path / "wide.xodr"
    src.write_text(crafted_xodr(["driving", "driving", "entry", "parking", "sidewalk"], ["driving", "exit", "sidewalk"]),
                   encoding="utf-8")
    import_map(src, "wide")
    assert map_stats("wide")["lanes_per_edge"] == {"2": 1, "3": 1}


def _default_netconvert(tmp_path, xodr: str):
    """The crafted road converted as CARLA made its SUMO nets: netconvert's default type map."""
    (tmp_path / "in.xodr").write_text(xodr, encoding="utf-8")
    run_netconvert(["--opendrive-files", "in.xodr", "--opendrive.import-all-lanes", "true",
                    "--no-warnings", "true", "--output-file", "default.net.xml"], cwd=tmp_path)
    return tmp_path / "default.net.xml"


def test_net_xml_with_parking_and_bidirectional_lanes_open_to_cars_is_mended(tmp_path):
    raw = _default_netconvert(tmp_path, crafted_xodr(["driving", "parking"], ["driving", "bidirectional"]))
    open_to_cars = {kind for kind, ln in _lanes_by_type(raw) if allows(ln, "passenger")}
    assert {"parking", "bidirectional"} <= open_to_cars  # what netconvert's default map does
    import_map(raw, "mended")
    _check_permissions(net_path("mended"), ("driving", "parking", "bidirectional"))
    assert map_info("mended")["lanes_closed"] == {"bidirectional": 1, "parking": 1}  # one of each per road side
    assert map_stats("mended")["lanes_per_edge"] == {"1": 2}
    # the raw net's statistics count its car lanes as the import leaves them (what CARLA's own net is compared by)
    raw_stats = net_stats(raw)
    for key in ("lanes_per_edge", "lanes_per_edge_mean", "drivable_edges"):
        assert raw_stats[key] == map_stats("mended")[key], key
    assert raw_stats["lanes_per_edge_mean"] == 1.0


def test_sidewalks_are_guessed_only_where_the_map_has_none(tmp_path):
    src = tmp_path / "bare.xodr"
    src.write_text(crafted_xodr(["driving"], ["driving"]), encoding="utf-8")
    import_map(src, "bare")
    stats = map_stats("bare")
    assert stats["import"]["sidewalks_guessed"] is True and stats["walkable_edges"] == 2
    _check_permissions(net_path("bare"), ("driving",))
    import_map(src, "bare_kept", sidewalks=False)
    stats = map_stats("bare_kept")
    assert stats["import"]["sidewalks_guessed"] is False and stats["walkable_edges"] == 0
