"""Hostile agents against the evaluator (``hostile_agents``): every attack ends as a counted failure
(``agent_error``), as a visible ``sim_error`` that keeps the entry off the ranking, or is harmless,
and no forged success reaches a records file, a report or a leaderboard.

Run as root, the agent process runs as ``nobody``; run as any other user, it keeps that user. The
tests assert what each case guarantees, and run the agent as the evaluator's own user
(``agent_user=None``) where they check what the evaluator itself must catch.
"""

import dataclasses
import json
import os
import pwd
import re
import time
from pathlib import Path

import pytest

import tiny_suite
from hostile_agents import for_tests
from hbmp_bench.evaluation import EpisodePool, RunnerLimits, evaluate, suite_tasks
from hbmp_bench.evaluation.channel import MAX_TEXT_BYTES
from hbmp_bench.evaluation.integrity import TamperedError
from hbmp_bench.evaluation.namespaces import UID_BASE, UID_COUNT
from hbmp_bench.evaluation.pool import FORKED, SANDBOX, isolation
from hbmp_bench.evaluation.leaderboard import entry_path, load_entries, results_document, submit, write_json
from hbmp_bench.metrics.records import AGENT_ERROR, DECISION_CAP, EpisodeRecord, read_records
from hbmp_bench.metrics.report import build_report, records_frame

pytestmark = pytest.mark.slow

ROOT = os.geteuid() == 0
QUICK = RunnerLimits(decision_timeout_s=3.0, agent_start_timeout_s=20.0, max_decisions=4)
"""Four decisions per episode: the attacks come at the second."""


def run(agents, limits=QUICK, episodes=1):
    """One Town01 Straight episode (event fidelity) per agent in one pool: records by class name."""
    tasks = [t for a in agents for t in suite_tasks("corl2017", a if ":" in a or a == "expert" else f"hostile_agents:{a}",
                                                        towns=["Town01"], tasks=["Straight"], episodes=episodes,
                                                        fidelity="event")]
    with EpisodePool(1, for_tests(limits)) as pool:
        return {o.record.agent.split(":")[-1]: o.record for o in pool.imap(tasks)}


def found(agent_dir, name):
    path = Path(agent_dir) / f"{name}.json"
    assert path.exists(), f"{name} never reported: its attack did not run"
    return json.loads(path.read_text())


def assert_counted_failure(record: EpisodeRecord, message: str):
    assert record.end_reason == AGENT_ERROR, record.error
    assert not record.success and record.driving_score == 0.0
    assert message in record.error


def test_channel_attacks_are_the_agents_failures(agent_dir):
    records = run(["GcPickleAgent", "UndecodableAgent", "RawBytesAgent", "HugeFrameAgent", "HugeErrorAgent",
                   "ClosingAgent", "FloodAgent", "expert"])
    assert found(agent_dir, "GcPickleAgent")["sent"]
    assert not (Path(agent_dir) / "pwned").exists()  # the crafted pickle never ran anywhere
    assert_counted_failure(records["GcPickleAgent"], "unknown reply tag b'\\x80'")
    assert_counted_failure(records["UndecodableAgent"], "reply text is not UTF-8")
    assert_counted_failure(records["RawBytesAgent"], "bytes announced, the limit is")
    assert_counted_failure(records["HugeFrameAgent"], "reply of 1073741824 bytes announced")
    assert found(agent_dir, "HugeFrameAgent")["stopped_by"] in ("BrokenPipeError", "ConnectionResetError")
    assert_counted_failure(records["HugeErrorAgent"], "agent act() raised")
    assert len(records["HugeErrorAgent"].error.encode()) <= MAX_TEXT_BYTES  # cut, not 10 MB in the records
    assert_counted_failure(records["ClosingAgent"], "closed its channel during act() at decision 1")
    # seen as data nobody asked for, or, when the two processes run in lockstep, as a second reply
    # to the same request arriving for the next one
    assert_counted_failure(records["FloodAgent"], "")
    assert re.search("more than one reply to a request|reply to request (\\d+), but the pending request is",
                     records["FloodAgent"].error)
    assert records["expert"].end_reason == DECISION_CAP and records["expert"].error == ""  # the pool is unharmed


def test_half_a_reply_neither_blocks_the_env_nor_trips_its_watchdog(agent_dir):
    # the watchdog shorter than the decision timeout, which must still end the stalled reply (2 s, not 1: on a
    # loaded machine the simulation's own start-up took a second without progress, a sim_error)
    limits = RunnerLimits(decision_timeout_s=2.5, watchdog_s=2.0, max_decisions=4, retries=0)
    start = time.monotonic()
    records = run(["HalfFrameAgent"], limits)
    assert_counted_failure(records["HalfFrameAgent"], "did not answer act() at decision 1 within 2.5 s")
    assert time.monotonic() - start < 30.0


def test_an_agent_that_never_builds_is_stopped():
    records = run(["SleepyBuildAgent"], RunnerLimits(agent_start_timeout_s=1.5, max_decisions=4))
    assert_counted_failure(records["SleepyBuildAgent"], "did not answer its start-up within 1.5 s")


def test_the_agent_process_is_confined(agent_dir):
    run(["SandboxProbeAgent"])
    facts = found(agent_dir, "SandboxProbeAgent")
    assert facts["sid"] == facts["pgid"] == facts["pid"]  # its own session: the pool kills it as a group
    assert facts["no_new_privs"] == 1 and facts["stdout_is_stderr"]
    mib = 2**20
    assert facts["rlimits"]["RLIMIT_AS"] == [QUICK.agent_memory_mb * mib] * 2
    assert facts["rlimits"]["RLIMIT_CPU"] == [QUICK.agent_cpu_s, QUICK.agent_cpu_s + 1]
    assert facts["rlimits"]["RLIMIT_FSIZE"] == [QUICK.agent_file_mb * mib] * 2
    assert facts["rlimits"]["RLIMIT_CORE"] == [0, 0]
    extra = {fd: target for fd, target in facts["fds"].items() if int(fd) > 2}
    sockets = [t for t in extra.values() if t.startswith("socket:")]
    pipes = [t for t in extra.values() if t.startswith("pipe:")]
    assert len(sockets) == 1 and len(pipes) == 1  # the channel and the lifeline, nothing inherited
    others = [t for t in extra.values() if t not in sockets + pipes]
    assert others == [] and facts["home"] == "/tmp"  # the sandbox shows every import folder; HOME is its /tmp
    assert facts["pid"] == 2  # in a PID namespace of its own, under bwrap's init
    if ROOT:  # a uid of its own for this evaluation, no account, not nobody's
        assert UID_BASE <= facts["uid"] == facts["euid"] == facts["gid"] < UID_BASE + UID_COUNT
        assert facts["groups"] == [] and not facts["regained_root"]
        assert facts["rlimits"]["RLIMIT_NPROC"] == [QUICK.agent_processes] * 2
    else:
        assert facts["uid"] == os.getuid()


def test_the_package_agents_keep_the_forked_confinement(agent_dir):
    """Registered agents are the package's own code: they are forked (fast), confined by the
    session, limits and (as root) ``agent_user``, as before the namespace sandbox."""
    tasks = suite_tasks("corl2017", "expert", towns=["Town01"], tasks=["Straight"], episodes=1, fidelity="event")
    assert isolation("expert", QUICK) == FORKED and isolation("hostile_agents:SandboxProbeAgent", QUICK) == SANDBOX
    assert isolation("hostile_agents:SandboxProbeAgent", RunnerLimits(trust_agent=True)) == FORKED
    with EpisodePool(1, QUICK) as pool:
        (outcome,) = list(pool.imap(tasks))
    assert outcome.record.end_reason == DECISION_CAP and outcome.record.error == ""


def test_the_simulator_is_out_of_reach(agent_dir):
    records = run(["LibsumoAgent"])
    attempts = found(agent_dir, "LibsumoAgent")
    assert set(attempts) == {"vehicles", "time", "move_to_goal", "speed"}
    assert all(value.startswith("failed") for value in attempts.values()), attempts
    assert records["LibsumoAgent"].end_reason == DECISION_CAP and records["LibsumoAgent"].route_completion < 0.05


def test_the_evaluators_memory_is_out_of_reach(agent_dir):
    """In its PID namespace the agent finds no process of the evaluator: its parent is the
    sandbox's init, there is no grandparent and no sibling (the env process)."""
    run(["ProcMemAgent"])
    targets = found(agent_dir, "ProcMemAgent")
    assert set(targets) == {"parent", "grandparent"}
    assert targets["parent"]["pid"] == 1 and targets["grandparent"]["pid"] == 0
    for role, outcome in targets.items():
        for attempt in ("read", "write", "ptrace", "environ"):
            assert "denied" in outcome[attempt], (role, outcome)


def test_the_evaluators_memory_is_out_of_reach_of_a_trusted_agent(agent_dir):
    """Without the sandbox (``trust_agent``) the evaluator's processes are visible, but
    non-dumpable: their memory, environment and ptrace are denied."""
    run(["ProcMemAgent"], dataclasses.replace(QUICK, trust_agent=True))
    targets = found(agent_dir, "ProcMemAgent")
    assert {"parent", "grandparent", "sibling0"} <= set(targets)  # fork server, this process, the env process
    for role, outcome in targets.items():
        for attempt in ("read", "write", "ptrace", "environ"):
            assert "denied" in outcome[attempt], (role, outcome)


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            text = fh.read()
    except OSError:
        return False
    return text[text.rfind(")") + 2] != "Z"


def test_forked_children_do_not_outlive_the_episode(agent_dir):
    from hostile_agents import LINGER_S

    records = run(["ForkingAgent"])
    children = found(agent_dir, "ForkingAgent")  # pids in the agent's own PID namespace
    assert set(children) == {"same_group", "own_group", "daemon"}
    time.sleep(LINGER_S + 0.5)
    assert not list(Path(agent_dir).glob("survivor-*"))  # none lived to leave its marker
    assert records["ForkingAgent"].end_reason == DECISION_CAP


def test_the_reaper_spares_the_fork_servers_other_children():
    """Another user of the same fork server (a training worker, say) is not an agent's orphan."""
    import multiprocessing as mp

    from hbmp_bench.evaluation.pool import default_start_method

    if default_start_method() != "forkserver":
        pytest.skip("orphans are reaped through the fork server")
    with EpisodePool(1, QUICK) as pool:
        worker = mp.get_context("forkserver").Process(target=time.sleep, args=(60,))
        worker.start()
        try:
            tasks = suite_tasks("corl2017", "hostile_agents:ForkingAgent", towns=["Town01"], tasks=["Straight"],
                                episodes=1, fidelity="event")
            (outcome,) = list(pool.imap(tasks))
            assert outcome.record.end_reason == DECISION_CAP and worker.is_alive()
        finally:
            worker.kill()
            worker.join()


def test_memory_is_capped(agent_dir):
    limits = RunnerLimits(decision_timeout_s=20.0, max_decisions=4, agent_memory_mb=2560)
    records = run(["MemoryHogAgent"], limits)
    hog = found(agent_dir, "MemoryHogAgent")
    assert hog["limit"] == 2560 * 2**20
    assert hog["error"].startswith("MemoryError") and hog["allocated"] < 2560 * 2**20
    assert records["MemoryHogAgent"].end_reason == DECISION_CAP  # refused memory, then harmless


def test_cpu_time_is_capped():
    limits = RunnerLimits(decision_timeout_s=20.0, max_decisions=4, agent_cpu_s=1)
    start = time.monotonic()
    records = run(["CpuHogAgent"], limits)
    assert_counted_failure(records["CpuHogAgent"], "agent process killed by SIGXCPU: it used up its CPU time limit of 1 s")
    assert time.monotonic() - start < 15.0


def test_garbage_after_driving_is_a_counted_failure_not_an_erased_episode(tmp_path):
    selection = dict(towns=["Town01"], tasks=["Straight"], episodes=1, workers=1, progress=False, fidelity="event")
    result = evaluate("corl2017", "hostile_agents:RedLightEraserAgent", out_dir=tmp_path, **selection)
    (record,) = result.records
    assert_counted_failure(record, "unknown reply tag")
    assert record.decisions == 11 and record.route_completion > 0.0  # it drove, and what it drove is kept
    report = build_report(records_frame(result.records))
    assert report["failures"].loc[("hostile_agents:RedLightEraserAgent", "Town01"), "agent_error"] == 1
    assert report["driving"].loc[("hostile_agents:RedLightEraserAgent", "all"), "episodes"] == 1
    assert report["success"].loc["Straight", "Town01"] == 0.0
    again = evaluate("corl2017", "hostile_agents:RedLightEraserAgent", out_dir=tmp_path, **selection)
    assert again.ran == 0 and again.skipped == 1  # not rerun on resume, unlike a sim_error


def _forge(monkeypatch, agent_dir, folder, **limits):
    records = folder / "corl2017__hostile_agents.RecordsForgerAgent.jsonl"
    monkeypatch.setenv("HBMP_TEST_RECORDS", str(records))
    return evaluate("corl2017", "hostile_agents:RecordsForgerAgent", towns=["Town01"], tasks=["Straight"], episodes=2,
                    workers=1, progress=False, fidelity="event", out_dir=folder, limits=for_tests(**limits))


def test_a_forger_with_the_evaluators_user_is_caught_and_its_file_moved_aside(agent_dir, monkeypatch, tmp_path):
    folder = Path(agent_dir) / "runs"
    folder.mkdir()
    with pytest.raises(TamperedError, match="changed while the evaluation ran"):
        _forge(monkeypatch, agent_dir, folder, agent_user=None, trust_agent=True)
    assert found(agent_dir, "RecordsForgerAgent")["records"] == "appended"  # the attack did write
    assert not list(folder.glob("*.jsonl"))  # moved aside: no report, resume or board reads it
    (tampered,) = folder.glob("*.jsonl.tampered")
    assert any(r.success for r in read_records(tampered))


@pytest.mark.skipif(not ROOT, reason="the agent switches to nobody only when the evaluator runs as root")
def test_a_trusted_forger_running_as_nobody_cannot_write(agent_dir, monkeypatch, tmp_path):
    folder = Path(agent_dir) / "runs"
    folder.mkdir()
    result = _forge(monkeypatch, agent_dir, folder, trust_agent=True)
    assert "denied" in found(agent_dir, "RecordsForgerAgent")["records"]
    assert [r.end_reason for r in result.records] == [AGENT_ERROR, AGENT_ERROR]
    assert not any(r.success for r in read_records(result.path))


def test_a_sandboxed_forger_cannot_even_see_the_records(agent_dir, monkeypatch, readable_dir):
    folder = readable_dir / "runs"  # writable by every user, and still not in the sandbox's view
    folder.mkdir()
    os.chmod(folder, 0o777)
    result = _forge(monkeypatch, agent_dir, folder)
    assert found(agent_dir, "RecordsForgerAgent")["records"] == "read denied: FileNotFoundError"
    assert [r.end_reason for r in result.records] == [AGENT_ERROR, AGENT_ERROR]
    assert [r.end_reason for r in result.records] == [AGENT_ERROR, AGENT_ERROR]
    assert not any(r.success for r in read_records(result.path))


def _board_with_an_entry(root: Path) -> Path:
    """A tiny-test board holding one honest entry (the forger copies it)."""
    honest = EpisodeRecord(suite=tiny_suite.NAME, town="Town01", task="Straight", episode=0, seed=1, agent="keep",
                           package_version="0", fidelity="event", success=False, route_completion=0.0,
                           collision_vehicle=0, collision_pedestrian=0, collision_other=0, wrong_lane=0, off_road=0,
                           red_light=0, timeout=True, duration_s=1.0, distance_m=0.0, route_length_m=100.0,
                           decisions=1, driving_score=0.0, end_reason="timeout")
    records = [honest, honest.__class__(**{**honest.to_dict(), "episode": 1})]
    doc = results_document(tiny_suite.NAME, "keep", records, towns=["Town01"], tasks=["Straight"], episodes=[0, 1],
                           fidelity="event")
    write_json(entry_path(root, tiny_suite.NAME, "keep", subset=False, fidelity="event"), doc)
    return root / tiny_suite.NAME


def test_a_forged_leaderboard_entry_is_refused(agent_dir, monkeypatch):
    root = Path(agent_dir) / "board"
    folder = _board_with_an_entry(root)
    monkeypatch.setenv("HBMP_TEST_BOARD", str(folder))
    limits = for_tests(env_factory="tiny_suite:make_env", agent_user=None, trust_agent=True)
    with pytest.raises(TamperedError, match="forged-champion.event.json"):
        submit(tiny_suite.NAME, "hostile_agents:RecordsForgerAgent", board_dir=root, fidelity="event", workers=1,
               limits=limits, progress=False)
    assert found(agent_dir, "RecordsForgerAgent")["board"] == "written"  # the attack did write
    assert [e["agent"] for e in load_entries(root, tiny_suite.NAME)] == ["keep"]  # the forgery is moved aside
    assert not entry_path(root, tiny_suite.NAME, "hostile_agents:RecordsForgerAgent", False, "event").exists()
    readme = folder / "README.md"
    assert not readme.exists() or "forged-champion" not in readme.read_text()


def test_killing_the_env_process_in_its_turn_is_the_agents_failure_not_a_retry(agent_dir, tmp_path):
    """Finding 6: a trusted agent (no sandbox: it sees and may signal the env process) that kills
    the env process while it has the turn fails its episode; no clean retry hides it."""
    limits = for_tests(env_factory="tiny_suite:make_env", agent_user=None, retries=1, trust_agent=True)
    path, doc = submit(tiny_suite.NAME, "hostile_agents:EnvKillerAgent", board_dir=tmp_path, fidelity="event",
                       workers=1, limits=limits, progress=False)
    assert "killed" in found(agent_dir, "EnvKillerAgent").values()
    assert doc["sim_errors"] == 0 and not any(e["success"] for e in doc["episodes"])
    records = read_records(next((tmp_path / tiny_suite.NAME / "runs").rglob("*.jsonl")))
    assert [r.end_reason for r in records] == [AGENT_ERROR, AGENT_ERROR]
    assert all("while the agent had the turn" in r.error for r in records)


def test_a_sandboxed_agent_finds_no_env_process_to_kill(agent_dir):
    records = run(["EnvKillerAgent"])
    assert found(agent_dir, "EnvKillerAgent") == {}  # its PID namespace holds no other process than its own
    assert_counted_failure(records["EnvKillerAgent"], "the env process survived")


@pytest.mark.skipif(not ROOT, reason="the agent switches to nobody only when the evaluator runs as root")
def test_a_trusted_agent_running_as_nobody_cannot_kill_the_env_process(agent_dir):
    records = run(["EnvKillerAgent"], dataclasses.replace(QUICK, trust_agent=True))
    outcome = found(agent_dir, "EnvKillerAgent")
    assert outcome and all(value.startswith("denied") for value in outcome.values())
    assert_counted_failure(records["EnvKillerAgent"], "the env process survived")


def test_an_agent_gets_only_an_env_it_may_ask_for_even_straight_through_the_pool(agent_dir):
    """The pool applies what agents ask for (``with_agent_env``) by itself, so its refusals hold
    there too: such an agent's episodes are its failures, and no env of its choosing is built."""
    records = run(["OwnEnvAgent", "EmptyRoadsAgent", "expert"])
    assert_counted_failure(records["OwnEnvAgent"], "asks for env_factory 'hostile_agents:make_env'")
    assert_counted_failure(records["EmptyRoadsAgent"], "asks for env options ['density']")
    assert records["OwnEnvAgent"].decisions == records["EmptyRoadsAgent"].decisions == 0
    assert records["expert"].end_reason == DECISION_CAP and records["expert"].error == ""
