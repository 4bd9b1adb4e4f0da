"""Ctrl-C in a terminal during ``hbmp-bench evaluate``: the whole process group gets SIGINT; the
command ends every child, keeps its records whole, says how to resume, and exits with 130."""

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
        "--episodes", "2", "--workers", "1", "--fidelity", "event", "--json"]


def _live_processes(group: int) -> list[str]:
    """Processes of a process group that are still running (not zombies): 'pid state name'."""
    found = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        name, rest = stat[stat.index("(") + 1: stat.rindex(")")], stat[stat.rindex(")") + 2:].split()
        state, pgrp = rest[0], int(rest[2])
        if pgrp == group and state not in ("Z", "X"):
            found.append(f"{entry} {state} {name}")
    return found


def test_ctrl_c_stops_cleanly_and_says_how_to_resume(tmp_path):
    out = tmp_path / "runs"
    path = records_path(out, "corl2017", AGENT)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), os.environ.get("PYTHONPATH", "")])}
    # a session of its own: the command, its fork server and its episode processes form one process group,
    # as a terminal's foreground job does
    proc = subprocess.Popen([sys.executable, "-m", "hbmp_bench.cli", *ARGS, "--out", str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while (not path.exists() or path.read_text().count("\n") < 1) and proc.poll() is None \
                and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)  # the second episode is under way
        assert proc.poll() is None, "the run ended before it could be interrupted"
        assert len(_live_processes(proc.pid)) >= 3, "the pool's children should be running"
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C does
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()

    assert proc.returncode == 130, stderr
    assert stdout == ""
    lines = stderr.splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    kept = read_records(path)
    assert 1 <= len(kept) < 4, "the interrupt should land mid-run"
    assert lines[0] == (f"hbmp-bench: interrupted: {len(kept)} of 4 episodes are recorded in {path}; "
                        "run the same evaluation again to resume")

    deadline = time.monotonic() + 10
    while _live_processes(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _live_processes(proc.pid) == [], "children outlived the interrupted command"

    text = path.read_text()
    assert text.endswith("\n") and all(json.loads(line) for line in text.splitlines())  # whole lines only

    # the hint holds: the same command finishes the rest, every episode exactly once
    sys.path.insert(0, str(Path(__file__).parent))
    try:
        assert main([*ARGS, "--out", str(out)]) == 0
    finally:
        sys.path.remove(str(Path(__file__).parent))
    records = read_records(path)
    assert collections.Counter((r.task, r.episode) for r in records) == {
        (task, i): 1 for task in ("Straight", "OneTurn") for i in range(2)}
    assert [r.to_dict() for r in records[: len(kept)]] == [r.to_dict() for r in kept]
