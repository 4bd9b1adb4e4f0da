"""Kill an evaluation mid-run, tear its last line, run it again: every episode exactly once."""

import collections
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hbmp_bench.cli import main
from hbmp_bench.evaluation import records_path
from hbmp_bench.metrics.records import read_records

pytestmark = pytest.mark.slow

AGENT = "misbehaving_agents:SlowExpert"
ARGS = ["evaluate", "--suite", "corl2017", "--agent", AGENT, "--towns", "Town01", "--tasks", "Straight", "OneTurn",
        "--episodes", "2", "--workers", "1", "--fidelity", "event"]


def _lines(path: Path) -> int:
    return path.read_text().count("\n") if path.exists() else 0


def test_kill_and_resume_keeps_every_episode_exactly_once(tmp_path):
    out = tmp_path / "runs"
    path = records_path(out, "corl2017", AGENT)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "hbmp_bench.cli", *ARGS, "--out", str(out), "--json"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while _lines(path) < 1 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = read_records(path)
    assert 1 <= len(before) < 4, "the kill should land mid-run"
    with open(path, "a") as fh:  # a kill in the middle of a write leaves half a line
        fh.write('{"suite": "corl2017", "town": "Town01", "task": "OneTu')

    assert main([*ARGS, "--out", str(out), "--json"]) == 0
    records = read_records(path)
    keys = collections.Counter((r.task, r.episode) for r in records)
    assert keys == {(task, i): 1 for task in ("Straight", "OneTurn") for i in range(2)}
    assert all(json.loads(line) for line in path.read_text().splitlines())  # the torn line is gone
    assert [r.to_dict() for r in records[: len(before)]] == [r.to_dict() for r in before]  # nothing rewritten
    assert all(r.success for r in records)

    # a third run finds nothing to do
    assert main([*ARGS, "--out", str(out), "--json"]) == 0
    assert len(read_records(path)) == 4
