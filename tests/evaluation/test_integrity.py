"""Results integrity, the sandbox's configuration and what an agent may ask of the env (no simulation)."""

import copy
import json
import os

import pytest

from hbmp_bench.evaluation import RunnerLimits
from hbmp_bench.evaluation.channel import AgentDescription
from hbmp_bench.evaluation.evaluate import evaluate, is_privileged, with_agent_env
from hbmp_bench.evaluation.integrity import BoardSnapshot, EvaluationRunning, RecordsLedger, TamperedError, records_lock
from hbmp_bench.evaluation.leaderboard import check_results, results_document
from hbmp_bench.evaluation.sandbox import agent_account
from hbmp_bench.metrics.records import EpisodeRecord, append_record, read_records, record_line

RECORD = EpisodeRecord(suite="corl2017", town="Town01", task="Straight", episode=0, seed=1, agent="a",
                       package_version="0", fidelity="event", success=False, route_completion=0.5,
                       collision_vehicle=0, collision_pedestrian=0, collision_other=0, wrong_lane=0, off_road=0,
                       red_light=1, timeout=False, duration_s=3.0, distance_m=40.0, route_length_m=80.0,
                       decisions=7, driving_score=0.0, end_reason="agent_error", error="garbage")


def forged(record: EpisodeRecord) -> EpisodeRecord:
    return EpisodeRecord(**{**record.to_dict(), "success": True, "end_reason": "goal", "driving_score": 100.0})


def test_the_ledger_keeps_what_this_run_appended(tmp_path):
    path = tmp_path / "r.jsonl"
    append_record(path, RECORD)  # from an earlier run: taken as it is
    ledger = RecordsLedger(path)
    second = EpisodeRecord(**{**RECORD.to_dict(), "episode": 1})
    ledger.append(second)
    assert ledger.records() == [RECORD, second]


@pytest.mark.parametrize("tamper", ["append", "rewrite_same_size", "truncate"])
def test_the_ledger_refuses_a_file_changed_behind_its_back_and_moves_it_aside(tmp_path, tamper):
    path = tmp_path / "r.jsonl"
    ledger = RecordsLedger(path)
    ledger.append(RECORD)
    if tamper == "append":
        append_record(path, forged(RECORD))
    elif tamper == "rewrite_same_size":
        text = path.read_text()
        path.write_text(text.replace('"success": false', '"success": true ').replace('"agent_error"', '"goal"       '))
        assert len(path.read_text()) == len(text)
    else:
        path.write_text("")
    with pytest.raises(TamperedError, match="changed while the evaluation ran"):
        ledger.append(EpisodeRecord(**{**RECORD.to_dict(), "episode": 1}))
    assert not path.exists() and (tmp_path / "r.jsonl.tampered").exists()


def test_the_ledger_checks_before_reading_results(tmp_path):
    path = tmp_path / "r.jsonl"
    ledger = RecordsLedger(path)
    ledger.append(RECORD)
    with open(path, "a") as fh:
        fh.write(record_line(forged(RECORD)))
    with pytest.raises(TamperedError):
        ledger.records()
    assert any(r.success for r in read_records(tmp_path / "r.jsonl.tampered"))


def test_one_evaluation_at_a_time_writes_a_records_file(tmp_path):
    path = tmp_path / "corl2017__expert.jsonl"
    append_record(path, RECORD)
    before = path.read_bytes()
    with records_lock(path):
        with pytest.raises(EvaluationRunning, match=f"pid {os.getpid()}.*{path.name}.*another --out"):
            with records_lock(path):
                pass
        with pytest.raises(EvaluationRunning):  # the evaluator takes it before it reads or writes anything
            evaluate("corl2017", "expert", towns=["Town01"], tasks=["Straight"], episodes=1, path=path,
                     progress=False)
    assert path.read_bytes() == before and not (tmp_path / (path.name + ".tampered")).exists()
    with records_lock(path):  # released on the way out, also after the refusal
        pass


def test_the_board_snapshot_names_added_changed_and_removed_files(tmp_path):
    for name in ("a.event.json", "b.event.json", "c.event.json"):
        (tmp_path / name).write_text("{}")
    (tmp_path / "README.md").write_text("generated")
    snapshot = BoardSnapshot(tmp_path)
    (tmp_path / "README.md").write_text("regenerated")  # not a results file
    snapshot.check_unchanged()
    (tmp_path / "a.event.json").write_text('{"complete": true}')
    (tmp_path / "b.event.json").unlink()
    (tmp_path / "forged.event.json").write_text("{}")
    with pytest.raises(TamperedError, match="a.event.json, b.event.json, forged.event.json"):
        snapshot.check_unchanged()
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "README.md", "a.event.json.tampered", "c.event.json", "forged.event.json.tampered"]


def test_results_files_must_agree_with_their_episodes():
    records = [RECORD, EpisodeRecord(**{**RECORD.to_dict(), "episode": 1, "end_reason": "sim_error"})]
    doc = results_document("corl2017", "a", records, towns=["Town01"], tasks=["Straight"], episodes=[0, 1],
                           fidelity="event")
    assert doc["sim_errors"] == 1 and not doc["complete"] and doc["privileged"] is False
    doc = json.loads(json.dumps(doc))
    unflagged = copy.deepcopy(doc)
    del unflagged["privileged"]
    with pytest.raises(ValueError, match="no privileged flag"):
        check_results(unflagged)
    lying = copy.deepcopy(doc)
    lying["sim_errors"] = 0
    with pytest.raises(ValueError, match="says sim_errors=0 but its episodes hold 1"):
        check_results(lying)
    lying = copy.deepcopy(doc)
    lying.update(complete=True, subset=False)
    with pytest.raises(ValueError, match="says complete"):
        check_results(lying)


def test_an_agent_may_only_ask_for_known_envs_and_observation_options():
    limits = RunnerLimits()
    control = with_agent_env(limits, AgentDescription("hbmp_bench.envs.control_env:ControlEnv",
                                                      (("observation", "vehicle_centric"),)))
    assert control.env_factory == "hbmp_bench.envs.control_env:ControlEnv"
    assert dict(control.env_kwargs) == {"observation": "vehicle_centric"}
    with pytest.raises(ValueError, match="may only ask for"):
        with_agent_env(limits, AgentDescription("hostile_agents:make_env"))
    with pytest.raises(ValueError, match=r"env options \['density'\]"):
        with_agent_env(limits, AgentDescription(None, (("density", "empty"),)))
    with pytest.raises(ValueError, match="observation kind"):
        with_agent_env(limits, AgentDescription(None, (("observation", "birds_eye"),)))
    privileged = with_agent_env(limits, AgentDescription(None, (("privileged", True),)))
    assert dict(privileged.env_kwargs) == {"privileged": True} and is_privileged(privileged)
    assert not is_privileged(control)
    with pytest.raises(ValueError, match="privileged must be True or False"):
        with_agent_env(limits, AgentDescription(None, (("privileged", "yes"),)))
    trusted = with_agent_env(RunnerLimits(env_factory="tiny_suite:make_env"), AgentDescription())
    assert trusted.env_factory == "tiny_suite:make_env"  # the evaluator may name any env


@pytest.mark.parametrize("field, value", [("agent_memory_mb", 0), ("agent_cpu_s", -1), ("agent_file_mb", 1.5),
                                          ("agent_processes", True), ("agent_user", "")])
def test_sandbox_limits_are_validated(field, value):
    with pytest.raises(ValueError, match=field):
        RunnerLimits(**{field: value})


def test_the_agent_user_must_exist_and_not_be_root(monkeypatch):
    monkeypatch.setattr(os, "geteuid", lambda: 0)
    assert agent_account("nobody").pw_name == "nobody"
    assert agent_account(None) is None
    with pytest.raises(ValueError, match="does not exist"):
        agent_account("no-such-user-hbmp")
    with pytest.raises(ValueError, match="is root"):
        agent_account("root")
    monkeypatch.setattr(os, "geteuid", lambda: 1000)
    assert agent_account("nobody") is None  # not root: the agent keeps the caller's user


def test_the_fork_server_preloads_trusted_modules_only():
    from hbmp_bench.evaluation.pool import PRELOAD, preload_for

    limits = RunnerLimits(agent_preload=("numpy.linalg",))
    assert preload_for("expert", RunnerLimits()) == PRELOAD
    assert {"torch", "tensordict", "hbmp_bench.policies.checkpoints"} <= set(preload_for("hbmp", limits))
    assert {"torch", "tensordict"} <= set(preload_for("runs/il/policy.pt", limits))
    plugin = preload_for("my_pkg.agents:Agent", limits)
    assert "torch" in plugin and "numpy.linalg" in plugin and not any("my_pkg" in m for m in plugin)
    with pytest.raises(ValueError, match="agent_preload"):
        RunnerLimits(agent_preload=("os; import evil",))
