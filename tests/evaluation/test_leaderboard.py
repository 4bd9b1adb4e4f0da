"""Leaderboard submissions: results files with provenance, the ranked README, refusal of stale files.

Full submissions run on ``tiny-test`` (two Town01 Straight episodes, registered by ``tiny_suite``);
a corl2017 subset checks that partial runs are kept apart and never ranked.
"""

import json
import shutil

import pytest

import tiny_suite
from hbmp_bench.agents.learned import checkpoint_fingerprint, shipped_checkpoint
from hbmp_bench.cli import main
from hbmp_bench.evaluation.evaluate import code_fingerprint
from hbmp_bench.evaluation import RunnerLimits
from hbmp_bench.evaluation.leaderboard import (
    ForgedResultsError,
    StaleResultsError,
    add_results,
    entry_path,
    load_entries,
    render_readme,
    runs_dir,
    submit,
)
from hbmp_bench.scenarios import get_suite

FIDELITY = "event"  # the fidelity these submissions run (fast)

pytestmark = pytest.mark.slow

TINY = RunnerLimits(env_factory="tiny_suite:make_env")  # children import the module that registers the suite


@pytest.fixture(scope="module")
def board(tmp_path_factory):
    """A board with two complete tiny-test entries (expert, keep)."""
    root = tmp_path_factory.mktemp("leaderboards")
    for agent in ("keep", "expert"):
        submit(tiny_suite.NAME, agent, board_dir=root, fidelity="event", workers=1, limits=TINY, progress=False)
    return root


def test_complete_entries_carry_provenance_and_are_ranked(board):
    doc = json.loads(entry_path(board, tiny_suite.NAME, "expert", subset=False, fidelity=FIDELITY).read_text())
    spec = get_suite(tiny_suite.NAME)
    assert doc["complete"] and not doc["subset"] and doc["expected_episodes"] == 2
    assert doc["suite_hash"] == spec.definition_hash() == doc["provenance"]["suite_definition_hash"]
    prov = doc["provenance"]
    for key in ("package_version", "git_commit", "date_utc", "machine", "libraries", "fidelity", "seeds", "wall_time_s"):
        assert key in prov
    assert prov["fidelity"] == doc["fidelity"] == "event"
    assert prov["seeds"]["suite_seed"] == spec.seed
    assert prov["machine"]["cpu_count"] >= 1 and prov["wall_time_s"] > 0
    assert prov["code_fingerprint"] == code_fingerprint() and prov["agent_fingerprint"] == ""  # no checkpoint
    assert [e["episode"] for e in doc["episodes"]] == [0, 1] and all(e["seed"] >= 0 for e in doc["episodes"])
    assert doc["summary"]["success_pct"] == 100.0 and doc["summary"]["episodes"] == 2
    assert doc["aggregates"]["success_pct_by_task"] == {"Straight": 100.0}
    keep = json.loads(entry_path(board, tiny_suite.NAME, "keep", subset=False, fidelity=FIDELITY).read_text())
    assert keep["summary"]["success_pct"] == 0.0
    assert doc["privileged"] is True and keep["privileged"] is False  # the expert asks for privileged=True

    readme = (board / tiny_suite.NAME / "README.md").read_text()
    assert spec.definition_hash() in readme and "## Fidelity: event" in readme
    rows = [line for line in readme.splitlines() if line.startswith("| 1 ") or line.startswith("| 2 ")]
    assert "| rank | agent | privileged | success % |" in readme
    assert rows[0].startswith("| 1 | `expert` | yes | 100.0") and rows[1].startswith("| 2 | `keep` | no | 0.0")
    assert "Partial runs" not in readme
    assert len(list(runs_dir(board, tiny_suite.NAME).glob("*.jsonl"))) == 2  # raw records kept for resuming


def test_a_learned_agents_entry_names_the_weights_it_ran(tmp_path):
    path, doc = submit(tiny_suite.NAME, "il", board_dir=tmp_path, fidelity="event", episodes=1, workers=1,
                       limits=TINY, progress=False)
    weights = checkpoint_fingerprint(shipped_checkpoint("il"))
    assert doc["provenance"]["agent_fingerprint"] == weights and len(weights) == 16
    assert json.loads(path.read_text())["provenance"]["agent_fingerprint"] == weights
    row = next(line for line in (tmp_path / tiny_suite.NAME / "README.md").read_text().splitlines()
               if line.startswith("| – | `il` |"))
    assert f"| {weights[:10]} |" in row


def test_a_resubmission_resumes_from_its_records(board):
    path, doc = submit(tiny_suite.NAME, "expert", board_dir=board, fidelity="event", workers=1, limits=TINY,
                       progress=False)
    assert doc["complete"] and doc["summary"]["episodes"] == 2
    assert doc["provenance"]["wall_time_s"] is None  # nothing ran: no wall time to report


def test_a_submission_the_board_would_refuse_writes_nothing(board, tmp_path, monkeypatch):
    """Records the board's checks refuse (here: a success that ended at the timeout; on the `hbmp` board a goal
    after a violation was one) stop the submission before its results file is written: the board stays
    renderable and open to the next submission."""
    import dataclasses

    from hbmp_bench.evaluation import leaderboard

    copy = tmp_path / "board"
    shutil.copytree(board, copy)
    real = leaderboard.evaluate

    def contradicting(*args, **kwargs):
        result = real(*args, **kwargs)
        first, *rest = result.records
        return dataclasses.replace(result, records=(
            dataclasses.replace(first, end_reason="timeout", timeout=True, success=True), *rest))

    monkeypatch.setattr(leaderboard, "evaluate", contradicting)
    before = sorted(p.name for p in (copy / tiny_suite.NAME).iterdir())
    with pytest.raises(ForgedResultsError, match="nothing was written"):
        submit(tiny_suite.NAME, "expert", board_dir=copy, fidelity="event", workers=1, limits=TINY, progress=False)
    assert sorted(p.name for p in (copy / tiny_suite.NAME).iterdir()) == before
    monkeypatch.setattr(leaderboard, "evaluate", real)
    render_readme(copy, tiny_suite.NAME)  # what is on the board still renders


def test_a_stale_results_file_is_refused_with_a_clear_message(board, tmp_path):
    copy = tmp_path / "board"
    shutil.copytree(board, copy)
    path = entry_path(copy, tiny_suite.NAME, "keep", subset=False, fidelity=FIDELITY)
    doc = json.loads(path.read_text())
    doc["suite_hash"] = "0123456789abcdef"
    path.write_text(json.dumps(doc))
    with pytest.raises(StaleResultsError, match="definition hash '0123456789abcdef'.*Rerun the submission"):
        render_readme(copy, tiny_suite.NAME)
    with pytest.raises(StaleResultsError):
        add_results(path, tmp_path / "other")
    with pytest.raises(StaleResultsError):  # refused before any episode runs
        submit(tiny_suite.NAME, "random", board_dir=copy, limits=TINY, progress=False)
    assert main(["leaderboard", "render", "--suite", tiny_suite.NAME, "--board-dir", str(copy)]) == 2


def test_a_format_1_results_file_reads_as_privileged(board, tmp_path):
    """Before the privileged flag (results format 2) every agent was handed the privileged scene."""
    path = entry_path(board, tiny_suite.NAME, "keep", subset=False, fidelity=FIDELITY)
    doc = json.loads(path.read_text())
    assert doc["format"] == 3 and doc["privileged"] is False and doc["salted"] is False
    old = {k: v for k, v in doc.items() if k not in ("privileged", "salted")} | {"format": 1}
    legacy = tmp_path / "legacy.json"
    legacy.write_text(json.dumps(old))
    target = add_results(legacy, tmp_path / "board")
    assert [(e["agent"], e["privileged"]) for e in load_entries(tmp_path / "board", tiny_suite.NAME)] == [("keep", True)]
    assert target.exists()


def test_add_installs_a_checked_results_file(board, tmp_path):
    target = add_results(entry_path(board, tiny_suite.NAME, "expert", subset=False, fidelity=FIDELITY), tmp_path)
    assert target == entry_path(tmp_path, tiny_suite.NAME, "expert", subset=False, fidelity=FIDELITY)
    assert [e["agent"] for e in load_entries(tmp_path, tiny_suite.NAME)] == ["expert"]
    assert "`expert`" in (tmp_path / tiny_suite.NAME / "README.md").read_text()


def test_a_corl2017_subset_is_written_apart_and_not_ranked(tmp_path, capsys):
    assert main(["leaderboard", "submit", "--suite", "corl2017", "--agent", "expert", "--towns", "Town01",
                 "--tasks", "Straight", "--episodes", "1", "--fidelity", "event", "--workers", "1",
                 "--board-dir", str(tmp_path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["subset"] and not out["complete"] and out["episodes"] == 1
    path = entry_path(tmp_path, "corl2017", "expert", subset=True, fidelity=FIDELITY)
    assert out["results"] == str(path) and path.name == f"expert.{FIDELITY}.subset.json"
    assert not entry_path(tmp_path, "corl2017", "expert", subset=False, fidelity=FIDELITY).exists()
    doc = json.loads(path.read_text())
    assert doc["selection"] == {"towns": ["Town01"], "tasks": ["Straight"], "episodes": [0]}
    readme = (tmp_path / "corl2017" / "README.md").read_text()
    assert "No complete entries yet." in readme
    assert "## Partial runs (not ranked)" in readme and "| – | `expert` | yes | 100.0" in readme


def test_each_fidelity_has_its_own_entry(tmp_path):
    """An agent submitted in event and in continuous fidelity keeps both entries (one table each)."""
    event = entry_path(tmp_path, "corl2017", "expert", subset=False, fidelity="event")
    continuous = entry_path(tmp_path, "corl2017", "expert", subset=False, fidelity="continuous")
    assert event != continuous and event.name == "expert.event.json"


def test_report_reads_a_board_as_it_reads_the_records_behind_it(board, tmp_path, capsys):
    """``hbmp-bench report leaderboards/<suite>`` gives the tables of the submitted records, so the
    README's tables come from the committed entries by one command."""
    from hbmp_bench.metrics.report import build_report, load_results

    from_board = build_report(load_results([board / tiny_suite.NAME]))
    from_records = build_report(load_results([runs_dir(board, tiny_suite.NAME)]))
    for view in ("success", "failures", "driving"):
        assert from_board[view].equals(from_records[view]), view
    assert set(from_board["success"].columns.get_level_values("agent")) == {"expert", "keep"}
    assert main(["report", str(board / tiny_suite.NAME), "--tasks", "Straight", "--out", str(tmp_path / "r")]) == 0
    assert (tmp_path / "r" / "failures.png").exists() and "expert" in capsys.readouterr().out
    assert main(["report", str(board / tiny_suite.NAME), "--tasks", "Nav", "--out", str(tmp_path / "r2")]) != 0
    err = capsys.readouterr().err  # the valid names: the CoRL2017 tasks and the scenario types
    assert "unknown task 'Nav'; valid: " in err and all(t in err for t in ("Navigation", "NavigationDynamic", "OneTurn",
                                                                          "Straight", "HardBrake", "CutIn"))
    assert not (tmp_path / "r2").exists()
