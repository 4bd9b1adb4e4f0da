"""run_transfer_episodes, the transfer table and ``hbmp-bench transfer``."""

import dataclasses

import pytest

from hbmp_bench.agents.base import AGENTS
from hbmp_bench.cli import main
from hbmp_bench.errors import UnknownNameError
from hbmp_bench.metrics.records import AGENT_ERROR, EpisodeRecord, read_records
from hbmp_bench.transfer.commands import TABLE_BEGIN, TABLE_END
from hbmp_bench.transfer.evaluate import run_transfer_episodes, transfer_table


class _Crashy:
    name = "crashy"

    def reset(self, info):
        pass

    def act(self, observation, info):
        raise RuntimeError("boom")


def _missing_checkpoint(**kwargs):
    raise FileNotFoundError("no shipped checkpoint for agent 'learned-test'")


@pytest.fixture
def test_agents(monkeypatch):
    monkeypatch.setitem(AGENTS, "crashy", _Crashy)
    monkeypatch.setitem(AGENTS, "learned-test", _missing_checkpoint)


def test_run_transfer_episodes_returns_records_per_episode():
    records = run_transfer_episodes("keep", "merge", 2, "vehicle_centric")
    assert [r.episode for r in records] == [0, 1] and [r.seed for r in records] == [0, 1]
    for r in records:
        assert isinstance(r, EpisodeRecord)
        assert (r.suite, r.town, r.task, r.agent, r.fidelity) == ("highway-transfer", "merge", "merge", "keep",
                                                                  "highway-env:vehicle_centric")
        assert r.success == (r.end_reason == "goal") and r.decisions > 0
    assert run_transfer_episodes("keep", "merge", 2, "vehicle_centric") == records


def test_run_transfer_episodes_errors(test_agents):
    with pytest.raises(UnknownNameError):
        run_transfer_episodes("keep", "parking", 1, "deformed")
    with pytest.raises(ValueError):
        run_transfer_episodes("keep", "merge", 0, "deformed")
    with pytest.raises(UnknownNameError):
        run_transfer_episodes("no-such-agent", "merge", 1, "deformed")
    with pytest.raises(FileNotFoundError):
        run_transfer_episodes("learned-test", "merge", 1, "deformed")
    records = run_transfer_episodes("crashy", "merge", 2, "deformed")
    assert [r.end_reason for r in records] == [AGENT_ERROR, AGENT_ERROR]
    assert not any(r.success for r in records) and "boom" in records[0].error


def _record(agent, scene, kind, episode, success, collisions):
    base = EpisodeRecord(
        suite="highway-transfer", town=scene, task=scene, episode=episode, seed=episode, agent=agent,
        package_version="0", fidelity=f"highway-env:{kind}", success=success, route_completion=1.0 if success else 0.5,
        collision_vehicle=collisions, collision_pedestrian=0, collision_other=0, wrong_lane=0, off_road=0,
        red_light=0, timeout=False, duration_s=1.0, distance_m=1.0, route_length_m=1.0, decisions=10,
        driving_score=0.0, end_reason="goal" if success else "collision")
    return base


def test_transfer_table_rates():
    records = [_record("expert", "merge", "deformed", k, k < 3, int(k == 3)) for k in range(4)]
    records += [_record("expert", "merge", "vehicle_centric", k, k < 1, int(k >= 2)) for k in range(4)]
    records += [_record("keep", "highway", "deformed", k, True, 0) for k in range(2)]
    table = transfer_table(records)
    assert list(table.index) == [("expert", "deformed"), ("expert", "vehicle_centric"), ("keep", "deformed")]
    assert list(table.columns) == [("highway", "success %"), ("highway", "collision %"),
                                   ("merge", "success %"), ("merge", "collision %")]
    assert table.loc[("expert", "deformed"), ("merge", "success %")] == 75.0
    assert table.loc[("expert", "deformed"), ("merge", "collision %")] == 25.0
    assert table.loc[("expert", "vehicle_centric"), ("merge", "success %")] == 25.0
    assert table.loc[("expert", "vehicle_centric"), ("merge", "collision %")] == 50.0
    assert table.loc[("keep", "deformed"), ("highway", "success %")] == 100.0
    # a rerun of the same episode replaces the earlier record
    rerun = dataclasses.replace(records[3], success=True, collision_vehicle=0)
    assert transfer_table(records + [rerun]).loc[("expert", "deformed"), ("merge", "success %")] == 100.0


def test_cli_evaluate_skips_a_missing_agent_and_writes_records_and_markdown(tmp_path, capsys, test_agents):
    out, md = tmp_path / "results", tmp_path / "transfer.md"
    md.write_text(f"# Transfer\n\nintro text\n\n{TABLE_BEGIN}\nold table\n{TABLE_END}\n\nclosing text\n")
    rc = main(["transfer", "evaluate", "--agent", "keep", "learned-test", "--scenes", "merge", "--episodes", "2",
               "--observation", "deformed", "--out", str(out), "--markdown", str(md)])
    captured = capsys.readouterr()
    assert rc == 0
    assert "agent 'learned-test' skipped: FileNotFoundError" in captured.err
    files = sorted(p.name for p in out.iterdir())
    assert files == ["highway-transfer__keep__merge__deformed.jsonl", "highway-transfer__keep__merge__deformed.timing.json"]
    assert len(read_records(out / files[0])) == 2
    text = md.read_text()
    assert text.startswith("# Transfer\n\nintro text\n\n" + TABLE_BEGIN) and text.endswith(TABLE_END + "\n\nclosing text\n")
    assert "old table" not in text and "| keep | deformed |" in text and "learned-test" in text

    rc = main(["transfer", "report", str(out), "--markdown", str(md)])
    assert rc == 0 and "| keep | deformed |" in md.read_text() and "closing text" in md.read_text()


def test_cli_errors(tmp_path, capsys, test_agents):
    assert main(["transfer", "evaluate", "--agent", "keep", "--scenes", "parking"]) == 2
    assert "valid: highway, intersection, merge, roundabout" in capsys.readouterr().err
    assert main(["transfer", "evaluate", "--agent", "learned-test", "--scenes", "merge", "--episodes", "1"]) == 2
    assert main(["transfer", "report", str(tmp_path)]) == 2
    assert main(["transfer", "scenes"]) == 0
    assert "HighwayTransfer-roundabout-v0" in capsys.readouterr().out
