"""Ctrl-C in a terminal during ``hbmp-bench evaluate`` and ``train`` (and SIGTERM to a background job): the whole process group gets
SIGINT; the command ends every child, keeps its files whole, says how to resume in one line, and
exits with 130."""

import collections
import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hbmp_bench.cli import main
from hbmp_bench.evaluation import records_path
from hbmp_bench.metrics.records import read_records
from hbmp_bench.policies.checkpoints import load_checkpoint

pytestmark = pytest.mark.slow

AGENTS_DIR = str(Path(__file__).parent / "evaluation")  # misbehaving_agents
AGENT = "misbehaving_agents:SlowExpert"
ARGS = ["evaluate", "--suite", "corl2017", "--agent", AGENT, "--towns", "Town01", "--tasks", "Straight", "OneTurn",
        "--episodes", "2", "--workers", "1", "--fidelity", "event", "--json"]


def _processes() -> dict[int, tuple[str, int, int]]:
    """Every process: pid -> (state, parent pid, process group)."""
    table = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()  # after "pid (name) "
        table[int(entry)] = (fields[0], int(fields[1]), int(fields[2]))
    return table


def _running(pid: int) -> set[int]:
    """``pid``'s process group and descendants (a sandbox may start a session of its own) that still
    run (zombies are over)."""
    table = _processes()
    found = {p for p, (_, _, group) in table.items() if group == pid}
    frontier = {pid}
    while frontier:
        frontier = {p for p, (_, parent, _) in table.items() if parent in frontier} - found
        found |= frontier
    return {p for p in found if p in table and table[p][0] not in ("Z", "X")}


def _lines(path: Path) -> int:
    return path.read_text().count("\n") if path.exists() else 0


def _interrupt(argv: list[str], started, children: int, background: bool = False) -> tuple[str, str]:
    """Run ``hbmp-bench argv`` as a terminal's foreground job, press Ctrl-C once ``started()`` holds
    (and a moment more), and check it exits with 130, one stderr line, and no process left behind.
    ``background``: instead, start it as ``cmd &`` does (SIGINT ignored) and stop it as ``kill`` or a
    scheduler does (SIGTERM to the command alone). Returns (stdout, stderr)."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([AGENTS_DIR, os.environ.get("PYTHONPATH", "")])}
    # a session of its own: the command and every process it starts share one process group, as in a terminal
    sigint = signal.SIG_IGN if background else signal.SIG_DFL  # as a shell starts `cmd &`, or a terminal `cmd`
    proc = subprocess.Popen([sys.executable, "-m", "hbmp_bench.cli", *argv], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, sigint))
    try:
        deadline = time.monotonic() + 180
        while not started() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)  # the next episode is under way
        assert proc.poll() is None, "the run ended before it could be interrupted"
        started_processes = _running(proc.pid)
        assert len(started_processes) > children, "the command's children should be running"
        if background:
            os.kill(proc.pid, signal.SIGTERM)  # what kill, systemd or a batch scheduler does
        else:
            os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C does
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, stderr
    assert len(stderr.splitlines()) == 1 and "Traceback" not in stderr, stderr
    deadline = time.monotonic() + 10
    while (started_processes & _running(proc.pid)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not started_processes & _running(proc.pid), "children outlived the interrupted command"
    return stdout, stderr


@pytest.mark.parametrize("background", [False, True], ids=["ctrl-c", "sigterm-to-a-background-job"])
def test_ctrl_c_stops_evaluate_cleanly_and_says_how_to_resume(tmp_path, background):
    out = tmp_path / "runs"
    path = records_path(out, "corl2017", AGENT)
    stdout, stderr = _interrupt(["evaluate", *ARGS[1:], "--out", str(out)], lambda: _lines(path) >= 1, children=2,
                                background=background)
    assert stdout == ""
    lines = stderr.splitlines()
    kept = read_records(path)
    assert 1 <= len(kept) < 4, "the interrupt should land mid-run"
    assert lines[0] == (f"hbmp-bench: interrupted: {len(kept)} of 4 episodes are recorded in {path}; "
                        "run the same evaluation again to resume")

    text = path.read_text()
    assert text.endswith("\n") and all(json.loads(line) for line in text.splitlines())  # whole lines only

    # the hint holds: the same command finishes the rest, every episode exactly once
    sys.path.insert(0, AGENTS_DIR)
    try:
        assert main([*ARGS, "--out", str(out)]) == 0
    finally:
        sys.path.remove(AGENTS_DIR)
    records = read_records(path)
    assert collections.Counter((r.task, r.episode) for r in records) == {
        (task, i): 1 for task in ("Straight", "OneTurn") for i in range(2)}
    assert [r.to_dict() for r in records[: len(kept)]] == [r.to_dict() for r in kept]


def test_ctrl_c_stops_train_cleanly_and_names_the_resume_command(tmp_path):
    out = tmp_path / "il"
    checkpoint = out / "checkpoint.pt"
    argv = ["train", "il", "--scenario", "hbmp_bench/Town02-Straight-v0", "--fidelity", "event", "--episodes", "40",
            "--workers", "1", "--save-every", "1", "--no-progress", "--out", str(out)]
    stdout, stderr = _interrupt(argv, checkpoint.exists, children=1)  # a checkpoint after each DAgger round
    assert stdout == ""
    done = load_checkpoint(str(checkpoint), kinds=("il",))["progress"]["episodes"]
    assert 1 <= done < 40, "the interrupt should land mid-run"
    prefix = f"hbmp-bench: interrupted: the last checkpoint is {checkpoint} ({done} of 40 episodes); resume with: "
    assert stderr.startswith(prefix), stderr
    command = shlex.split(stderr[len(prefix):])
    assert command == ["hbmp-bench", "train", "il", "--scenario", "hbmp_bench/Town02-Straight-v0", "--episodes", "40",
                       "--workers", "1", "--seed", "0", "--out", str(out), "--fidelity", "event",
                       "--resume", str(checkpoint), "--save-every", "1"]

    # what the interrupt left resumes (one more round instead of all 40 episodes, to keep the test short)
    command[command.index("--episodes") + 1] = str(done + 1)
    assert main([*command[1:], "--no-progress"]) == 0
    assert load_checkpoint(str(checkpoint), kinds=("il",))["progress"]["episodes"] == done + 1
