"""The smoke helper and its pytest plugin (the ``hbmp_smoke`` fixture from the ``pytest11`` entry point)."""

import os
import subprocess
import sys
import textwrap

import pytest

from hbmp_bench.scenarios import TASKS
from hbmp_bench.testing import SmokeConfig, SmokeFailure, smoke_run

pytestmark = pytest.mark.slow

FAST = dict(fidelity="event")  # the checks do not depend on the fidelity; event keeps them quick


@pytest.mark.parametrize("agent", ["expert", "random", "keep", "hbmp", "flat"])
def test_the_package_agents_pass_the_smoke_run(hbmp_smoke, agent):
    """Each in the env it asks for: the expert's privileged fields, hbmp's metric R_t, flat's control env
    (which always runs the bicycle model: continuous fidelity)."""
    result = hbmp_smoke(agent, **(FAST if agent != "flat" else {"fidelity": "continuous"}))
    assert [o.record.task for o in result.outcomes] == list(TASKS)
    assert result.decisions == len(TASKS) * SmokeConfig().max_decisions
    assert 0.0 < result.max_decision_s < SmokeConfig().max_decision_s


@pytest.mark.parametrize(
    ("agent", "options", "expected"),
    [
        ("misbehaving_agents:RaisingAgent", {}, "RuntimeError: the policy network exploded"),
        ("misbehaving_agents:InvalidActionAgent", {}, "invalid action 7 at decision 0"),
        ("misbehaving_agents:SlowAgent", {"max_decision_s": 0.1}, "did not answer act() at decision 0 within 0.1 s"),
        ("misbehaving_agents:BrokenInitAgent", {}, "ImportError: weights file missing"),
    ],
)
def test_bad_agents_fail_with_a_readable_message(agent, options, expected):
    with pytest.raises(SmokeFailure) as info:
        smoke_run(agent, SmokeConfig(tasks=("Straight", "OneTurn"), **FAST, **options))
    message = str(info.value)
    assert message.startswith(f"agent {agent!r} failed the hbmp_bench smoke run (Town01")
    assert "- Town01/Straight/0, agent error after" in message and "- Town01/OneTurn/0" in message
    assert expected in message


def test_smoke_config_rejects_bad_options():
    with pytest.raises(ValueError, match="Town01"):
        SmokeConfig(town="Town9")
    with pytest.raises(ValueError, match="episode"):
        SmokeConfig(episode=99)


def test_the_three_line_test_of_an_agent_author(readable_dir):
    """A fresh pytest run finds the fixture through the entry point and reports a bad agent readably.

    The folder is readable by everyone: run as root, the agent process imports the author's module
    as an unprivileged user."""
    tmp_path = readable_dir
    (tmp_path / "author_agents.py").write_text(textwrap.dedent("""
        class Good:
            name = "good"
            def reset(self, info): pass
            def act(self, observation, info): return 4

        class Bad(Good):
            def act(self, observation, info): return {"steer": 0.1}
    """))
    (tmp_path / "test_author.py").write_text(textwrap.dedent("""
        def test_good(hbmp_smoke):
            hbmp_smoke("author_agents:Good", tasks=("Straight",), fidelity="event")

        def test_bad(hbmp_smoke):
            hbmp_smoke("author_agents:Bad", tasks=("Straight",), fidelity="event")
    """))
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(tmp_path)],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "1 failed, 1 passed" in run.stdout
    assert "agent 'author_agents:Bad' failed the hbmp_bench smoke run" in run.stdout
    assert "action must be an integer or a 1-D vector of numbers, got dict" in run.stdout
    assert "Traceback" not in run.stdout  # the failure is the message, not the plugin's stack
