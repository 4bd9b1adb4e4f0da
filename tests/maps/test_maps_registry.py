"""Map names, paths, user imports (.net.xml and OpenDRIVE)."""

from __future__ import annotations

import hashlib
import re
import json
import shutil

import pytest

from hbmp_bench.errors import UnknownNameError, UserError
from hbmp_bench.maps import (TOWNS, available_maps, import_map, map_hash, map_info, map_stats, net_path,
                             remove_map, user_maps_dir)
from hbmp_bench.scenarios import road_network

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
    info = map_stats("my_town")["import"]
    # driving lanes only carry cars and sidewalks are there: no netconvert run; only the speed limits of the
    # lanes whose bends a car cannot take at the road's limit are lowered, nothing else of the file changes
    assert info["netconvert_runs"] == [] and info["source"] == "copy.net.xml"
    assert info["curve_speed_lanes"] > 0
    without_speeds = re.compile(rb' speed="[^"]*"')
    assert without_speeds.sub(b"", stored.read_bytes()) == without_speeds.sub(b"", net_path("Town02").read_bytes())
    assert info["source_sha256"] == hashlib.sha256(src.read_bytes()).hexdigest() != info["net_sha256"]
    # a net that needs nothing (an import of an import) is stored byte for byte
    again = import_map(stored, "again")
    assert again.read_bytes() == stored.read_bytes() and map_info("again")["curve_speed_lanes"] == 0


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


def test_import_records_provenance(tmp_path):
    src = tmp_path / "straight.xodr"
    src.write_text(XODR, encoding="utf-8")
    import_map(src, "straight", like="Town02")
    info = map_info("straight")
    assert info["source"] == "straight.xodr" and info["format"] == "xodr"
    assert info["source_sha256"] == hashlib.sha256(src.read_bytes()).hexdigest()
    assert info["net_sha256"] == hashlib.sha256(net_path("straight").read_bytes()).hexdigest()
    assert map_hash("straight") == info["net_sha256"][:16]
    assert info["netconvert"].startswith("Eclipse SUMO netconvert")
    assert "--opendrive-files" in info["netconvert_runs"][0] and "--tls.guess" in info["netconvert_runs"][0]
    assert info["like"] == "Town02" and info["lights"] == "source" and info["imported_at"][:2] == "20"
    assert json.loads((user_maps_dir() / "straight.map.json").read_text()) == info


def test_import_refuses_to_overwrite_without_force_and_remove(tmp_path):
    src = tmp_path / "straight.xodr"
    src.write_text(XODR, encoding="utf-8")
    import_map(src, "straight")
    before = map_info("straight")
    assert len(road_network("straight").edge_length) < 10  # the process's cached lane graph of the first import
    other = tmp_path / "copy.net.xml"
    shutil.copyfile(net_path("Town02"), other)
    with pytest.raises(UserError, match="--force"):
        import_map(other, "straight")
    assert map_info("straight") == before
    import_map(other, "straight", force=True)
    assert map_info("straight")["source"] == "copy.net.xml"
    assert map_stats("straight")["drivable_edges"] == map_stats("Town02")["drivable_edges"]
    assert road_network("straight").edge_length == road_network("Town02").edge_length  # read again, not cached
    remove_map("straight")
    assert "straight" not in available_maps() and _user_files() == []
    with pytest.raises(UnknownNameError):
        road_network("straight")
    with pytest.raises(UnknownNameError):
        remove_map("straight")
    with pytest.raises(UserError):
        remove_map("Town01")


def test_import_refuses_bad_like_and_lights(tmp_path):
    src = tmp_path / "straight.xodr"
    src.write_text(XODR, encoding="utf-8")
    with pytest.raises(UnknownNameError, match="Town02"):
        import_map(src, "x", like="Town9")
    with pytest.raises(UnknownNameError, match="lawful"):
        import_map(src, "x", lights="green")
    assert _user_files() == []


def test_hostile_and_truncated_files_fail_naming_the_file(tmp_path):
    bomb = tmp_path / "bomb.xodr"
    bomb.write_text('<?xml version="1.0"?><!DOCTYPE OpenDRIVE [<!ENTITY a "aaaaaaaaaa">'
                    '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]><OpenDRIVE>&b;</OpenDRIVE>', encoding="utf-8")
    truncated_xodr = tmp_path / "cut.xodr"
    truncated_xodr.write_text(XODR[: len(XODR) // 2], encoding="utf-8")
    truncated_net = tmp_path / "cut.net.xml"
    text = net_path("Town02").read_text(encoding="utf-8")
    truncated_net.write_text(text[: len(text) // 2], encoding="utf-8")
    binary = tmp_path / "noise.xodr"
    binary.write_bytes(bytes(range(256)) * 8)
    # a declaration after a long comment, and a net that sumolib would read (its entities expanded)
    padding = "<!--" + "x" * 5000 + "-->\n"
    late_bomb = tmp_path / "late.xodr"
    late_bomb.write_text('<?xml version="1.0"?>' + padding + '<!DOCTYPE OpenDRIVE [<!ENTITY a "aaaa">]>'
                         + XODR[XODR.index("<OpenDRIVE>"):], encoding="utf-8")
    late_net = tmp_path / "late.net.xml"
    late_net.write_text(padding + '<!DOCTYPE net [<!ENTITY a "aaaa">]>' + text[text.index("<net "):], encoding="utf-8")
    empty_xodr, empty_net, blank = tmp_path / "empty.xodr", tmp_path / "empty.net.xml", tmp_path / "blank.xodr"
    empty_xodr.write_bytes(b"")
    empty_net.write_bytes(b"")
    blank.write_text("  \n", encoding="utf-8")
    not_xml = tmp_path / "words.net.xml"
    not_xml.write_text("hello, not a net", encoding="utf-8")
    wrong = tmp_path / "town.xml"
    wrong.write_text(XODR, encoding="utf-8")
    cases = {bomb: "document type", late_bomb: "document type", late_net: "document type", truncated_xodr: "",
             truncated_net: "", binary: "", empty_xodr: "is empty", empty_net: "is empty", blank: "is empty",
             not_xml: "not well-formed", wrong: ".xodr or a SUMO .net.xml"}
    for src, says in cases.items():
        with pytest.raises(ValueError) as info:
            import_map(src, "bad")
        message = str(info.value)
        assert src.name in message and says in message, message
        assert "input.net.xml" not in message and "hbmp_import_" not in message, message  # no staged copy named
    assert _user_files() == []


def test_an_import_is_reproducible_byte_for_byte(tmp_path):
    """Records and boards are keyed to the imported net's SHA-256: the same source imports to the same bytes
    (netconvert's header, with its date and temporary paths, is dropped)."""
    src = tmp_path / "straight.xodr"
    src.write_text(XODR, encoding="utf-8")
    first = import_map(src, "first", lights="lawful").read_bytes()
    second = import_map(src, "second", lights="lawful").read_bytes()
    assert first == second and b"generated on" not in first
    assert map_info("first")["net_sha256"] == map_info("second")["net_sha256"] == hashlib.sha256(first).hexdigest()
