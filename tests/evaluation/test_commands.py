"""``hbmp-bench evaluate``, ``report`` and ``leaderboard`` from the command line."""

import json

import pytest

from hbmp_bench.cli import COMMAND_MODULES, main


def test_evaluation_commands_are_registered():
    assert "hbmp_bench.evaluation.commands" in COMMAND_MODULES


def test_bad_input_exits_2_naming_the_valid_choices(tmp_path, capsys):
    assert main(["evaluate", "--backend", "dask", "--out", str(tmp_path)]) == 2
    assert "process, ray" in capsys.readouterr().err
    assert main(["evaluate", "--agent", "expret", "--out", str(tmp_path)]) == 2
    assert "expert" in capsys.readouterr().err
    assert main(["report", str(tmp_path / "nowhere")]) == 2
    assert "no records file or folder" in capsys.readouterr().err
    assert main(["report", str(tmp_path)]) == 2  # a folder without records
    assert "no .jsonl records" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())  # nothing half-written


@pytest.mark.slow
def test_evaluate_then_report(tmp_path, capsys):
    common = ["--towns", "Town02", "--tasks", "Straight", "--episodes", "1", "--fidelity", "event", "--workers", "1",
              "--out", str(tmp_path / "runs"), "--json"]
    for agent in ("expert", "keep"):
        assert main(["evaluate", "--agent", agent, *common]) == 0
        summary = json.loads(capsys.readouterr().out)
        assert summary["ran"] == 1 and summary["skipped"] == 0 and summary["missing"] == 0
        assert summary["records"].endswith(f"corl2017__{agent}.jsonl")
    assert main(["evaluate", "--agent", "expert", *common]) == 0
    assert json.loads(capsys.readouterr().out)["skipped"] == 1

    assert main(["report", str(tmp_path / "runs"), "--json"]) == 0
    views = json.loads(capsys.readouterr().out)
    assert views["success"] == [{"task": "Straight", "Town02 / expert": 100.0, "Town02 / keep": 0.0}]
    failures = {row["result_set"]: row for row in views["failures"]}
    assert failures["expert"]["success"] == 1 and failures["keep"]["timeout"] == 1
    report_dir = tmp_path / "runs" / "report"
    for name in ("success", "failures", "driving", "km_between", "coverage"):
        assert (report_dir / f"{name}.csv").exists() and (report_dir / f"{name}.md").exists()
    assert (report_dir / "failures.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "## success" in (report_dir / "report.md").read_text()
