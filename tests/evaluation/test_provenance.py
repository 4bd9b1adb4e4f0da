"""A resumed evaluation never mixes episodes of two checkpoints, two nets imported under one map
name, or two versions of the package under one records file."""

import importlib
import json
import shutil

import pytest

from hbmp_bench.agents.learned import LearnedAgent, shipped_checkpoint
from hbmp_bench.errors import UserError
from hbmp_bench.evaluation.evaluate import check_provenance, code_fingerprint, evaluate
from hbmp_bench.evaluation.integrity import RecordsSeal
from hbmp_bench.maps import import_map, map_hash, net_path


@pytest.fixture(autouse=True)
def _isolated_user_maps(tmp_path, monkeypatch):
    monkeypatch.setenv("HBMP_BENCH_DATA", str(tmp_path / "hbmp_data"))


def _import(tmp_path, town, name, **kwargs):
    src = tmp_path / f"{town}.net.xml"
    shutil.copyfile(net_path(town), src)
    import_map(src, name, **kwargs)


def _provenance(records):
    return json.loads(records.with_name(records.name + ".provenance.json").read_text())


def test_learned_agents_are_fingerprinted_by_their_weights():
    il, hbmp = LearnedAgent(shipped_checkpoint("il")), LearnedAgent(shipped_checkpoint("hbmp"))
    assert len(il.fingerprint) == 16 and il.fingerprint != hbmp.fingerprint
    assert LearnedAgent(shipped_checkpoint("il")).fingerprint == il.fingerprint


def test_the_code_fingerprint_covers_the_package_code():
    assert len(code_fingerprint()) == 16 and code_fingerprint() == code_fingerprint()


def test_resuming_with_other_weights_is_refused(tmp_path):
    records = tmp_path / "corl2017__hbmp.jsonl"
    check_provenance(records, "hbmp", "aaaa", ["Town01"])  # a new evaluation: what runs is noted
    assert _provenance(records) == {"code": code_fingerprint(), "agent": "aaaa", "maps": {}}
    records.write_text('{"episode": 0}\n')
    check_provenance(records, "hbmp", "aaaa", ["Town01"])  # the same weights: resume
    with pytest.raises(UserError, match="another 'hbmp' run .*agent aaaa, now bbbb.*--out"):
        check_provenance(records, "hbmp", "bbbb", ["Town01"])
    assert _provenance(records)["agent"] == "aaaa"


def test_resuming_with_another_version_of_the_package_is_refused(tmp_path, monkeypatch):
    """The rule-based expert has no weights: its code is the package's."""
    records = tmp_path / "corl2017__expert.jsonl"
    check_provenance(records, "expert", "", ["Town01"])
    records.write_text('{"episode": 0}\n')
    monkeypatch.setattr(importlib.import_module("hbmp_bench.evaluation.evaluate"), "code_fingerprint", lambda: "0123456789abcdef")
    with pytest.raises(UserError, match="another 'expert' run .*code .*, now 0123456789abcdef"):
        check_provenance(records, "expert", "", ["Town01"])


def test_records_without_provenance_are_not_resumed(tmp_path):
    records = tmp_path / "corl2017__expert.jsonl"
    records.write_text('{"episode": 0}\n')
    with pytest.raises(UserError, match="unknown provenance"):
        check_provenance(records, "expert", "", ["Town01"])


def test_resuming_on_another_net_under_the_same_name_is_refused(tmp_path):
    records = tmp_path / "runs" / "corl2017__expert.jsonl"
    records.parent.mkdir()
    _import(tmp_path, "Town02", "mine")
    check_provenance(records, "expert", "", ["Town01", "mine"])  # a new evaluation: the net is noted
    assert _provenance(records)["maps"] == {"mine": map_hash("mine")}  # built-in towns are the code's
    records.write_text('{"episode": 0}\n')
    check_provenance(records, "expert", "", ["mine"])  # the same net: resume
    _import(tmp_path, "Town01", "mine", force=True)
    with pytest.raises(UserError, match="another 'expert' run .*map 'mine'.*--out"):
        check_provenance(records, "expert", "", ["mine"])
    RecordsSeal(records, records.with_name(records.name + ".provenance.json")).write()  # as an evaluator leaves them
    with pytest.raises(UserError, match="map 'mine'"):
        evaluate("corl2017", "expert", towns=["mine"], tasks=["Straight"], episodes=1,
                 out_dir=tmp_path / "runs", progress=False)
    assert records.read_text() == '{"episode": 0}\n'
