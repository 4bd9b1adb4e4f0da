"""A resumed evaluation never mixes two nets imported under one map name."""

import shutil

import pytest

from hbmp_bench.errors import UserError
from hbmp_bench.evaluation.evaluate import check_map_hashes, evaluate
from hbmp_bench.maps import import_map, map_hash, net_path


@pytest.fixture(autouse=True)
def _isolated_user_maps(tmp_path, monkeypatch):
    monkeypatch.setenv("HBMP_BENCH_DATA", str(tmp_path / "hbmp_data"))


def _import(tmp_path, town, name, **kwargs):
    src = tmp_path / f"{town}.net.xml"
    shutil.copyfile(net_path(town), src)
    import_map(src, name, **kwargs)


def test_resuming_on_another_net_under_the_same_name_is_refused(tmp_path):
    records = tmp_path / "runs" / "corl2017__expert.jsonl"
    records.parent.mkdir()
    _import(tmp_path, "Town02", "mine")
    check_map_hashes(records, ["Town01", "mine"])  # a new evaluation: the net is noted
    side = tmp_path / "runs" / "corl2017__expert.jsonl.maps"
    assert side.read_text().count(map_hash("mine")) == 1 and "Town01" not in side.read_text()
    records.write_text('{"episode": 0}\n')
    check_map_hashes(records, ["mine"])  # the same net: resume
    _import(tmp_path, "Town01", "mine", force=True)
    with pytest.raises(UserError, match="another map named 'mine'.*--out"):
        check_map_hashes(records, ["mine"])
    with pytest.raises(UserError, match="another map named 'mine'"):
        evaluate("corl2017", "expert", towns=["mine"], tasks=["Straight"], episodes=1,
                 out_dir=tmp_path / "runs", check_agent=False, progress=False)
    assert records.read_text() == '{"episode": 0}\n'
