"""Smoke test of ``hbmp-bench bench --quick``: every part runs and the JSON is complete (no timing asserts)."""

import json

import pytest

from hbmp_bench.bench import BenchConfig, format_table
from hbmp_bench.cli import main


@pytest.mark.slow
def test_bench_quick_writes_complete_json(tmp_path, capsys):
    out = tmp_path / "throughput.json"
    assert main(["bench", "--quick", "--json", "--out", str(out)]) == 0
    printed = json.loads(capsys.readouterr().out)
    written = json.loads(out.read_text())
    assert printed == written
    assert written["machine"]["cpu_count"] >= 1 and written["machine"]["package_version"]
    town = written["towns"]["Town01"]
    raw = town["raw_sumo"]
    assert raw["steps"] == BenchConfig.quick().raw_steps and raw["steps_per_s"] > 0
    assert raw["vehicles"] > 1 and raw["pedestrians"] > 0  # the NavigationDynamic traffic is there
    for fidelity in ("event", "continuous"):
        row = town[fidelity]
        assert row["decisions"] > 0 and row["sim_steps"] >= row["decisions"]
        assert row["ratio_to_raw"] == pytest.approx(row["sim_steps_per_s"] / raw["steps_per_s"], abs=1e-3)
        assert row["latency"]["sumo_step"]["n"] >= row["sim_steps"]
        assert row["latency"]["occupancy"]["n"] >= row["decisions"]
    assert town["event"]["sim_steps"] == town["event"]["decisions"]  # one 0.1 s step per event decision
    assert town["continuous"]["latency"]["planner"]["n"] > 0
    assert town["event"]["latency"]["planner"]["n"] == 0
    assert set(written["highway_env"]) == {"highway-fast-v0", "intersection-v0"}
    assert [r["workers"] for r in written["scaling"]] == [1]
    assert written["scaling"][0]["peak_rss_mb_per_process"] > 0
    names = [c["name"] for c in written["targets"]]
    assert "Town01 continuous sim steps/s / raw SUMO" in names and "Town01 event decisions/s / highway-fast-v0" in names
    assert all(c["passed"] == (c["value"] >= c["target"]) for c in written["targets"])
    assert "targets:" in format_table(written)


def test_bench_config_rejects_bad_values():
    with pytest.raises(ValueError):
        BenchConfig(towns=())
    with pytest.raises(ValueError):
        BenchConfig(scaling_workers=(0,))
    with pytest.raises(ValueError):
        BenchConfig(scaling_fidelity="fast")
