"""Map names, paths, user imports (.net.xml and OpenDRIVE)."""

from __future__ import annotations

import shutil

import pytest

from hbmp_bench.errors import UnknownNameError
from hbmp_bench.maps import (TOWNS, available_maps, import_map, map_stats, net_path,
                             user_maps_dir)

# One straight 200 m road with one driving lane per direction.
XODR = """<?xml version="1.0" encoding="UTF-8"?>
<OpenDRIVE>
  <header revMajor="1" revMinor="4" name="straight" version="1.00"/>
  <road name="main" length="200.0" id="1" junction="-1">
    <link/>
    <planView>
      <geometry s="0.0" x="0.0" y="0.0" hdg="0.0" length="200.0"><line/></geometry>
    </planView>
    <lanes>
      <laneSection s="0.0">
        <left>
          <lane id="1" type="driving" level="false"><link/>
            <width sOffset="0.0" a="3.5" b="0" c="0" d="0"/></lane>
        </left>
        <center><lane id="0" type="none" level="false"><link/></lane></center>
        <right>
          <lane id="-1" type="driving" level="false"><link/>
            <width sOffset="0.0" a="3.5" b="0" c="0" d="0"/></lane>
        </right>
      </laneSection>
    </lanes>
  </road>
</OpenDRIVE>
"""


def _user_files():
    d = user_maps_dir()
    return sorted(p.name for p in d.rglob("*")) if d.exists() else []


def test_builtin_maps():
    assert available_maps()[: len(TOWNS)] == TOWNS
    for town in TOWNS:
        assert net_path(town).is_file()


def test_user_maps_dir_follows_env(tmp_path, monkeypatch):
    monkeypatch.setenv("HBMP_BENCH_DATA", str(tmp_path))
    assert user_maps_dir() == tmp_path / "maps"


def test_unknown_name_lists_valid_names():
    with pytest.raises(UnknownNameError) as info:
        net_path("Town99")
    msg = str(info.value)
    assert "Town99" in msg and all(t in msg for t in TOWNS)
    with pytest.raises(UnknownNameError):
        map_stats("nope")


def test_import_net_xml(tmp_path):
    src = tmp_path / "copy.net.xml"
    shutil.copyfile(net_path("Town02"), src)
    stored = import_map(src, "my_town")
    assert stored.parent == user_maps_dir() and stored.is_file()
    assert "my_town" in available_maps()
    assert net_path("my_town") == stored
    assert map_stats("my_town") == map_stats("Town02")


def test_import_xodr(tmp_path):
    src = tmp_path / "straight.xodr"
    src.write_text(XODR, encoding="utf-8")
    import_map(str(src), "straight")
    s = map_stats("straight")
    assert s["drivable_edges"] == 2
    assert s["lanes_per_edge"] == {"1": 2}
    assert s["directed_road_length_m"] == pytest.approx(400.0, abs=1.0)


@pytest.mark.parametrize("suffix, content", [
    (".net.xml", "this is not xml <<<"),
    (".net.xml", "<net></net>"),
    (".net.xml", "<notanet/>"),
    (".xodr", "garbage"),
    (".xodr", "<OpenDRIVE><road/></OpenDRIVE>"),
])
def test_import_garbage_leaves_nothing(tmp_path, suffix, content):
    src = tmp_path / f"bad{suffix}"
    src.write_text(content, encoding="utf-8")
    with pytest.raises(ValueError):
        import_map(src, "bad")
    assert _user_files() == []
    assert "bad" not in available_maps()


def test_import_rejects_wrong_extension_missing_file_and_shadowing(tmp_path):
    wrong = tmp_path / "map.txt"
    wrong.write_text("<net/>", encoding="utf-8")
    with pytest.raises(ValueError):
        import_map(wrong, "x")
    with pytest.raises(FileNotFoundError):
        import_map(tmp_path / "missing.net.xml", "x")
    src = tmp_path / "copy.net.xml"
    shutil.copyfile(net_path("Town01"), src)
    for name in ("Town01", "town01", "", "../evil"):
        with pytest.raises(ValueError):
            import_map(src, name)
    assert _user_files() == []
