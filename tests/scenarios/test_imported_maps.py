"""Task parameters of imported maps: their own size, a borrowed town's, pedestrians only where they can walk."""

from __future__ import annotations

import shutil

import pytest

from hbmp_bench.maps import import_map, map_hash, net_path
from hbmp_bench.scenarios import road_network, suite_episodes, traffic_for
from hbmp_bench.scenarios.suites import MEAN_ROUTE_LENGTH_M, mean_route_lengths


@pytest.fixture(autouse=True)
def _isolated_user_maps(tmp_path, monkeypatch):
    monkeypatch.setenv("HBMP_BENCH_DATA", str(tmp_path / "hbmp_data"))


def _copy(tmp_path, town: str):
    src = tmp_path / f"{town}.net.xml"
    shutil.copyfile(net_path(town), src)
    return src


def _road_length(town: str) -> float:
    return sum(road_network(town).edge_length.values())


def test_an_import_without_like_scales_from_its_own_size(tmp_path):
    import_map(_copy(tmp_path, "Town02"), "small")
    # the same net as Town02, but Town02's CoRL figures are not borrowed: Town01's scaled by road length
    ratio = _road_length("small") / _road_length("Town01")
    assert 0.3 < ratio < 0.7
    assert mean_route_lengths("small") == pytest.approx([m * ratio for m in MEAN_ROUTE_LENGTH_M["Town01"]], abs=0.06)
    t = traffic_for("small", "NavigationDynamic", None)
    assert (t.vehicles, t.pedestrians) == (round(20 * ratio), round(50 * ratio))


def test_like_gives_the_towns_counts_and_lengths(tmp_path):
    import_map(_copy(tmp_path, "Town02"), "as02", like="Town02")
    assert mean_route_lengths("as02") == MEAN_ROUTE_LENGTH_M["Town02"]
    assert traffic_for("as02", "NavigationDynamic", None).vehicles == 15
    assert traffic_for("as02", "Navigation", "dense").pedestrians == 150
    lengths = [e.route_length_m for e in suite_episodes("corl2017", "as02", "OneTurn")]
    assert len(lengths) == 25 and 0.5 * 170 <= sum(lengths) / 25 <= 1.5 * 170  # CoRL2017's Town02 One turn


BARE_ROAD = """<?xml version="1.0" encoding="UTF-8"?>
<OpenDRIVE>
  <header revMajor="1" revMinor="4" name="bare" version="1.00"/>
  <road name="r" length="400.0" id="1" junction="-1">
    <link/>
    <planView><geometry s="0.0" x="0.0" y="0.0" hdg="0.0" length="400.0"><line/></geometry></planView>
    <lanes><laneSection s="0.0">
      <left><lane id="1" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></left>
      <center><lane id="0" type="none" level="false"><link/></lane></center>
      <right><lane id="-1" type="driving" level="false"><link/><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane></right>
    </laneSection></lanes>
  </road>
</OpenDRIVE>
"""


def test_no_pedestrians_where_none_can_walk(tmp_path):
    src = tmp_path / "bare.xodr"
    src.write_text(BARE_ROAD, encoding="utf-8")
    import_map(src, "bare", sidewalks=False)
    import_map(src, "walk")
    assert traffic_for("bare", "NavigationDynamic", None).pedestrians == 0
    assert traffic_for("walk", "NavigationDynamic", None).pedestrians > 0


def test_episodes_follow_the_net_imported_under_a_name(tmp_path):
    import_map(_copy(tmp_path, "Town02"), "m", like="Town02")
    first, h1 = suite_episodes("corl2017", "m", "Straight"), map_hash("m")
    import_map(_copy(tmp_path, "Town01"), "m", like="Town01", force=True)
    second, h2 = suite_episodes("corl2017", "m", "Straight"), map_hash("m")
    assert h1 != h2 and first != second
    assert all(e.route[0] in road_network("Town01").edge_lanes for e in second)
    assert sum(e.route_length_m for e in second) / 25 > sum(e.route_length_m for e in first) / 25  # 200 m vs 100 m
