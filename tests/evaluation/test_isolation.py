"""The agent runs in its own process: failures are recorded per episode, the run goes on, and the
agent cannot reach the simulation."""

import shutil
from pathlib import Path

import pytest

from hbmp_bench.evaluation import EpisodePool, Job, RunnerLimits, evaluate, run_job, suite_tasks
from hbmp_bench.metrics.records import AGENT_ERROR

pytestmark = pytest.mark.slow

SELECTION = dict(towns=["Town01"], tasks=["Straight"], episodes=2, workers=1, progress=False, fidelity="event")
"""Event fidelity keeps these runner tests fast; isolation does not depend on the fidelity."""


def test_raising_agent_fails_its_episodes_and_the_run_finishes(tmp_path):
    result = evaluate("corl2017", "misbehaving_agents:RaisingAgent", out_dir=tmp_path, **SELECTION)
    assert result.ran == 2 and result.missing == 0
    for record in result.records:
        assert record.end_reason == AGENT_ERROR and not record.success
        assert "RuntimeError: the policy network exploded" in record.error
        assert record.decisions == 3  # three decisions executed before the fourth act raised


def test_agent_process_runs_one_numeric_thread_unless_the_caller_asks(tmp_path, monkeypatch):
    one = dict(SELECTION, episodes=1)
    result = evaluate("corl2017", "misbehaving_agents:ThreadReportingAgent", out_dir=tmp_path / "a", **one)
    assert "torch threads=1" in result.records[0].error
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    result = evaluate("corl2017", "misbehaving_agents:ThreadReportingAgent", out_dir=tmp_path / "b", **one)
    assert "torch threads=2" in result.records[0].error


def test_hanging_agent_is_stopped_by_the_decision_timeout(tmp_path):
    result = evaluate("corl2017", "misbehaving_agents:HangingAgent", out_dir=tmp_path,
                      limits=RunnerLimits(decision_timeout_s=1.0), **SELECTION)
    assert result.ran == 2 and result.missing == 0
    for record in result.records:
        assert record.end_reason == AGENT_ERROR and not record.success
        assert "did not answer act() at decision 2 within 1 s" in record.error
        assert record.decisions == 2


def test_mixed_failures_in_one_pool_then_a_good_agent_still_drives():
    limits = RunnerLimits(decision_timeout_s=1.0, agent_start_timeout_s=30.0)
    agents = ["misbehaving_agents:InvalidActionAgent", "misbehaving_agents:FloatActionAgent",
              "misbehaving_agents:DyingAgent", "misbehaving_agents:BrokenInitAgent", "expert"]
    tasks = [t for a in agents for t in suite_tasks("corl2017", a, towns=["Town01"], tasks=["Straight"], episodes=1,
                                                        fidelity="event")]
    with EpisodePool(1, limits) as pool:
        by_agent = {o.record.agent.split(":")[-1]: o.record for o in pool.imap(tasks)}
    assert "invalid action 7 at decision 0" in by_agent["InvalidActionAgent"].error
    assert "action must be an integer or a 1-D vector of numbers, got float 1.5" in by_agent["FloatActionAgent"].error
    assert "agent process exited" in by_agent["DyingAgent"].error
    assert "agent could not be built" in by_agent["BrokenInitAgent"].error
    assert "weights file missing" in by_agent["BrokenInitAgent"].error
    for name in ("InvalidActionAgent", "FloatActionAgent", "DyingAgent", "BrokenInitAgent"):
        assert by_agent[name].end_reason == AGENT_ERROR and not by_agent[name].success
    assert by_agent["expert"].success and by_agent["expert"].error == ""


def test_an_agent_importing_the_simulator_cannot_move_the_ego(tmp_path, monkeypatch, agent_dir):
    log = Path(agent_dir) / "cheat.log"
    monkeypatch.setenv("HBMP_TEST_CHEAT_LOG", str(log))
    # In this process the same cheat works: the agent shares libsumo with the simulation.
    (inline,), _, _ = run_job(Job("corl2017", "Town01", "Straight", "misbehaving_agents:CheatingAgent", (0,), "event"))
    assert log.read_text().splitlines() == ["moved"]
    assert inline.route_completion > 0.5
    log.unlink()
    # Evaluated, the agent runs in its own process: no network is loaded there.
    result = evaluate("corl2017", "misbehaving_agents:CheatingAgent", out_dir=tmp_path / "runs",
                      limits=RunnerLimits(agent_env=("HBMP_TEST_CHEAT_LOG",), agent_writable=(agent_dir,)),
                      **{**SELECTION, "episodes": 1})
    (record,) = result.records
    (attempt,) = log.read_text().splitlines()
    assert attempt.startswith("failed:")
    assert not record.success and record.end_reason == "timeout"
    assert record.route_completion < 0.05 and record.distance_m < 1.0


def test_a_checkpoint_only_the_caller_can_read_still_loads(tmp_path):
    """Checkpoints are built by the package's own code before the agent process switches user
    (run as root: to nobody), so a private checkpoint file works; a copy of the shipped hbmp."""
    from hbmp_bench.agents.learned import shipped_checkpoint

    private = tmp_path / "private" / "hbmp.pt"
    private.parent.mkdir(mode=0o700)
    shutil.copy(shipped_checkpoint("hbmp"), private)
    private.chmod(0o600)
    tasks = suite_tasks("corl2017", str(private), towns=["Town01"], tasks=["Straight"], episodes=1, fidelity="event")
    # the pool itself gives the policy the env it was trained on (hbmp's R_t is the metric profile)
    with EpisodePool(1, RunnerLimits(max_decisions=3)) as pool:
        (outcome,) = list(pool.imap(tasks))
    assert outcome.record.end_reason == "decision_cap" and outcome.record.error == ""
    assert outcome.record.decisions == 3
