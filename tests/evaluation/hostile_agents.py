"""Hostile agents: submissions that attack the evaluator, loaded as ``hostile_agents:Class`` in the
adversarial tests.

Each is a real agent (the Agent protocol) that runs in the agent process like any submission and
attacks from there: through its channel, the simulator, ``/proc``, signals, forks, files and
memory. What an attack achieved is written as JSON to ``<HBMP_TEST_AGENT_DIR>/<Class>.json`` (a
folder every user may write), so the tests can tell a blocked attack from one that never ran.
"""

from __future__ import annotations

import ctypes
import gc
import json
import os
import pickle
import resource
import signal
import socket
import struct
import sys
import time
from pathlib import Path

from hbmp_bench.agents.expert import ExpertAgent

KEEP = 4
LINGER_S = 2.0
"""How long the children of ``ForkingAgent`` wait before they leave their marker [s]."""
MARKER = "pwned"
"""File a payload creates in ``HBMP_TEST_AGENT_DIR`` if it ever runs in the evaluator."""


def report(name: str, data: dict) -> None:
    """Write what the attack found to ``<HBMP_TEST_AGENT_DIR>/<name>.json`` (last write wins)."""
    folder = os.environ.get("HBMP_TEST_AGENT_DIR")
    if folder:
        path = Path(folder) / f"{name}.json"
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(data, sort_keys=True))
        os.replace(tmp, path)


def channel_socket() -> socket.socket:
    """The agent's own channel, found the way the original attacker found it: in ``gc``, as the
    socket held by the agent process's end of the channel."""
    for obj in gc.get_objects():
        if type(obj).__name__ == "AgentEnd" and isinstance(getattr(obj, "sock", None), socket.socket):
            return obj.sock
    raise RuntimeError("no channel found in gc")


def pending_request() -> int:
    """The number of the request the agent process is answering, read from its serving loop's
    frame (what an attacker who read the package's code would do)."""
    frame = sys._getframe()
    while frame is not None:
        if frame.f_code.co_name == "agent_main" and "number" in frame.f_locals:
            return frame.f_locals["number"]
        frame = frame.f_back
    raise RuntimeError("not inside the agent process's serving loop")


def reply(tag: bytes, body: bytes = b"") -> bytes:
    """A framed reply to the pending request, made by hand."""
    return frame(tag + struct.pack("<I", pending_request()) + body)


def frame(payload: bytes) -> bytes:
    """A frame as the channel (and multiprocessing's Connection) writes it: 4-byte length, then bytes."""
    return struct.pack("!i", len(payload)) + payload


class _Base:
    name = "hostile"

    def __init__(self):
        self.decisions = 0

    def reset(self, info):
        self.decisions = 0

    def act(self, observation, info):
        self.decisions += 1
        if self.decisions == 2:
            self.attack()
        return KEEP

    def attack(self) -> None:
        raise NotImplementedError


class _Payload:
    """Unpickling it runs code: it leaves ``MARKER`` (the reported payload marked the episode as
    reached; any code that runs could)."""

    def __reduce__(self):
        code = "import os, pathlib; pathlib.Path(os.environ['HBMP_TEST_AGENT_DIR'], 'pwned').write_text(str(os.getpid()))"
        return (exec, (code,))


class GcPickleAgent(_Base):
    """The reported attack: finds its connection with ``gc`` and sends a crafted pickle in place of
    an action (``("action", payload)``, as the old protocol's tuples were)."""

    def attack(self):
        sock = channel_socket()
        sock.sendall(frame(pickle.dumps(("action", _Payload()), protocol=2)))
        report(type(self).__name__, {"sent": True, "pid": os.getpid()})


class UndecodableAgent(_Base):
    """Sends a well-framed reply the env cannot decode: an error text that is not UTF-8."""

    def attack(self):
        channel_socket().sendall(reply(b"E", b"\xff\xfe\xfd not utf-8"))


class RawBytesAgent(_Base):
    """Writes unframed garbage on its channel."""

    def attack(self):
        channel_socket().sendall(b"\xde\xad\xbe\xef" * 64)


class HugeFrameAgent(_Base):
    """Announces a 1 GiB reply and starts streaming it."""

    def attack(self):
        sock = channel_socket()
        sent = 0
        try:
            sock.sendall(struct.pack("!I", 1 << 30))
            chunk = b"A" * (1 << 20)
            for _ in range(64):
                sock.sendall(chunk)
                sent += len(chunk)
        except OSError as exc:
            report(type(self).__name__, {"sent": sent, "stopped_by": type(exc).__name__})
            raise


class HugeErrorAgent(_Base):
    """Raises with a 10 MB message (the agent process cuts it to the channel's text limit)."""

    def attack(self):
        raise RuntimeError("x" * 10_000_000)


class ClosingAgent(_Base):
    """Closes its own channel mid-episode and carries on."""

    def attack(self):
        sock = channel_socket()
        sock.shutdown(socket.SHUT_RDWR)
        sock.close()


class FloodAgent(_Base):
    """Answers one request with a thousand copies of a valid reply."""

    def attack(self):
        sock = channel_socket()
        action = reply(b"A", struct.pack("<q", 0))
        for _ in range(1000):
            sock.sendall(action)


class HalfFrameAgent(_Base):
    """Sends half a reply (its header promises 100 bytes, 10 come) and stalls: the env must not
    block on the rest, nor stop its heartbeats."""

    def attack(self):
        channel_socket().sendall(struct.pack("!I", 100) + b"A" * 10)
        time.sleep(10**6)


class SleepyBuildAgent(_Base):
    """Never finishes building."""

    def __init__(self):
        super().__init__()
        time.sleep(10**6)


class LibsumoAgent(_Base):
    """Imports the simulator and tries to read the scene and move the ego to its goal."""

    def reset(self, info):
        super().reset(info)
        self.key = info.get("episode_key", "Town01/Straight/0")  # no longer in info: the tests run this one

    def attack(self):
        import libsumo

        from hbmp_bench.scenarios import suite_episodes

        town, task, index = self.key.split("/")
        goal = suite_episodes("corl2017", town, task)[int(index)]
        tries = {
            "vehicles": lambda: libsumo.vehicle.getIDList(),
            "time": lambda: libsumo.simulation.getTime(),
            "move_to_goal": lambda: libsumo.vehicle.moveTo("ego", goal.goal_lane, goal.goal_pos),
            "speed": lambda: libsumo.vehicle.setSpeed("ego", 30.0),
        }
        outcome = {}
        for name, call in tries.items():
            try:
                value = call()
                outcome[name] = f"ok: {value!r}"[:200]
            except Exception as exc:  # noqa: BLE001
                outcome[name] = f"failed: {type(exc).__name__}"
        report(type(self).__name__, outcome)


def _read_mem(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/maps") as fh:
            first = fh.readline()
    except OSError as exc:
        return f"maps denied: {type(exc).__name__}"
    start = int(first.split("-")[0], 16)
    try:
        with open(f"/proc/{pid}/mem", "rb") as fh:
            fh.seek(start)
            data = fh.read(16)
    except OSError as exc:
        return f"mem denied: {type(exc).__name__}"
    return f"read {len(data)} bytes"


def _write_mem(pid: int) -> str:
    try:
        fh = open(f"/proc/{pid}/mem", "r+b")
    except OSError as exc:
        return f"denied: {type(exc).__name__}"
    fh.close()
    return "opened for writing"


def _ptrace(pid: int) -> str:
    libc = ctypes.CDLL(None, use_errno=True)
    libc.ptrace.restype = ctypes.c_long
    if libc.ptrace(16, pid, None, None) == 0:  # PTRACE_ATTACH
        libc.ptrace(17, pid, None, None)  # PTRACE_DETACH
        return "attached"
    return f"denied: errno {ctypes.get_errno()}"


def _parent(pid: int) -> int:
    with open(f"/proc/{pid}/stat") as fh:
        text = fh.read()
    return int(text[text.rfind(")") + 2:].split()[1])


def _siblings() -> list[int]:
    me, parent = os.getpid(), os.getppid()
    out = []
    for name in os.listdir("/proc"):
        if name.isdigit() and int(name) != me:
            try:
                if _parent(int(name)) == parent:
                    out.append(int(name))
            except (OSError, ValueError, IndexError):
                continue
    return out


def evaluator_processes() -> dict[str, int]:
    """The evaluator's processes an agent can find: its parent (the fork server), the parent's
    parent (the evaluator itself) and its siblings (env processes)."""
    parent = os.getppid()
    found = {"parent": parent}
    try:
        found["grandparent"] = _parent(parent)
    except (OSError, ValueError, IndexError):
        pass
    for k, pid in enumerate(_siblings()):
        found[f"sibling{k}"] = pid
    return found


class ProcMemAgent(_Base):
    """Reads (and tries to open for writing, and to ptrace) the memory of the evaluator's processes."""

    def attack(self):
        outcome = {}
        for role, pid in evaluator_processes().items():
            outcome[role] = {"pid": pid, "read": _read_mem(pid), "write": _write_mem(pid), "ptrace": _ptrace(pid)}
            try:
                with open(f"/proc/{pid}/environ", "rb") as fh:
                    outcome[role]["environ"] = f"read {len(fh.read())} bytes"
            except OSError as exc:
                outcome[role]["environ"] = f"denied: {type(exc).__name__}"
        report(type(self).__name__, outcome)


class EnvKillerAgent(_Base):
    """SIGKILLs its sibling processes (the env process that runs its episode), then gives up."""

    def attack(self):
        outcome = {}
        for pid in _siblings():
            try:
                os.kill(pid, signal.SIGKILL)
                outcome[str(pid)] = "killed"
            except OSError as exc:
                outcome[str(pid)] = f"denied: {type(exc).__name__}"
        report(type(self).__name__, outcome)
        time.sleep(1.0)  # give the kill time to land before this episode could end
        raise RuntimeError("the env process survived")


def _linger(marker: str, seconds: float) -> None:
    """In a forked child: wait, then leave ``marker`` (proof it outlived the episode)."""
    try:
        time.sleep(seconds)
        Path(os.environ["HBMP_TEST_AGENT_DIR"], marker).write_text(str(os.getpid()))
    finally:
        os._exit(0)


class ForkingAgent(_Base):
    """Forks children meant to outlive the episode: one in its process group, one in a group of its
    own, and a double-forked daemon in a session of its own. Each leaves a marker after ``LINGER_S``."""

    def attack(self):
        pids = {}
        pid = os.fork()
        if pid == 0:
            _linger("survivor-group", LINGER_S)
        pids["same_group"] = pid
        pid = os.fork()
        if pid == 0:
            os.setpgid(0, 0)
            _linger("survivor-own-group", LINGER_S)
        pids["own_group"] = pid
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.setsid()
            grandchild = os.fork()
            if grandchild == 0:
                _linger("survivor-daemon", LINGER_S)
            os.write(write, str(grandchild).encode())
            os._exit(0)
        os.waitpid(pid, 0)
        pids["daemon"] = int(os.read(read, 32))
        report(type(self).__name__, pids)


class MemoryHogAgent(_Base):
    """Allocates 256 MiB blocks (at most 6 GiB) until the allocation fails, then keeps driving."""

    def attack(self):
        import numpy as np

        blocks, error = [], ""
        try:
            for _ in range(24):
                blocks.append(np.ones(256 * 2**20, dtype=np.uint8))
        except MemoryError as exc:
            error = f"MemoryError: {exc}"[:200]
        allocated = sum(b.nbytes for b in blocks)
        del blocks
        report(type(self).__name__, {"allocated": allocated, "error": error,
                                     "limit": resource.getrlimit(resource.RLIMIT_AS)[1]})


class CpuHogAgent(_Base):
    """Spins on the CPU without end (threads or not, the process's CPU time is what counts)."""

    def attack(self):
        while True:
            pass


class RecordsForgerAgent(_Base):
    """Appends a forged goal record for its own episode to the records file (``HBMP_TEST_RECORDS``)
    and drops a forged, complete, top-ranked results file into the leaderboard folder
    (``HBMP_TEST_BOARD``), then fails its episode."""

    def reset(self, info):
        super().reset(info)
        self.key = info.get("episode_key", "Town01/Straight/0")  # no longer in info: the tests run this one

    def attack(self):
        outcome = {}
        records = os.environ.get("HBMP_TEST_RECORDS")
        if records:
            outcome["records"] = self._forge_records(Path(records))
        board = os.environ.get("HBMP_TEST_BOARD")
        if board:
            outcome["board"] = self._forge_board(Path(board))
        report(type(self).__name__, outcome)
        raise RuntimeError("forged what it could")

    def _forge_records(self, path: Path) -> str:
        try:
            lines = path.read_text().splitlines()
        except OSError as exc:
            return f"read denied: {type(exc).__name__}"
        town, task, index = self.key.split("/")
        template = json.loads(lines[-1]) if lines else {}
        forged = {**template, "town": town, "task": task, "episode": int(index), "success": True, "end_reason": "goal",
                  "route_completion": 1.0, "driving_score": 100.0, "error": "", "agent": template.get("agent", "")}
        try:
            with open(path, "a") as fh:
                for k in range(4):
                    fh.write(json.dumps({**forged, "episode": k}) + "\n")
        except OSError as exc:
            return f"write denied: {type(exc).__name__}"
        return "appended"

    def _forge_board(self, folder: Path) -> str:
        sources = sorted(folder.glob("*.json"))
        if not sources:
            return "no entry to copy"
        doc = json.loads(sources[0].read_text())
        doc.update(agent="forged-champion", complete=True, subset=False, sim_errors=0)
        doc["summary"] = {**doc["summary"], "success_pct": 100.0, "mean_driving_score": 100.0}
        doc["episodes"] = [{**e, "success": True, "end_reason": "goal"} for e in doc["episodes"]]
        try:
            (folder / f"forged-champion.{doc['fidelity']}.json").write_text(json.dumps(doc))
        except OSError as exc:
            return f"write denied: {type(exc).__name__}"
        return "written"


class RedLightEraserAgent(ExpertAgent):
    """The second reported attack: drives like the expert, then, before the episode can be
    judged (a red light run, a bad route), sends bytes the env cannot decode, hoping the episode
    is dropped as a simulator error."""

    name = "eraser"
    ERASE_AT = 12

    def reset(self, info):
        super().reset(info)
        self.decisions = 0

    def act(self, observation, info):
        self.decisions += 1
        if self.decisions == self.ERASE_AT:
            channel_socket().sendall(frame(b"\x80\x04garbage"))
        return super().act(observation, info)


class SandboxProbeAgent(_Base):
    """Reports what its process may do: user, session, descriptors, limits, privileges."""

    def attack(self):
        fds = {}
        for name in os.listdir("/proc/self/fd"):
            try:
                fds[name] = os.readlink(f"/proc/self/fd/{name}")
            except OSError:
                continue
        libc = ctypes.CDLL(None, use_errno=True)
        try:
            os.setuid(0)
            regained = os.getuid() == 0
        except PermissionError:
            regained = False
        out, err = os.fstat(1), os.fstat(2)
        report(type(self).__name__, {
            "pid": os.getpid(), "uid": os.getuid(), "euid": os.geteuid(), "gid": os.getgid(), "groups": os.getgroups(),
            "sid": os.getsid(0), "pgid": os.getpgid(0), "fds": fds, "regained_root": regained,
            "no_new_privs": libc.prctl(39, 0, 0, 0, 0),
            "stdout_is_stderr": (out.st_dev, out.st_ino) == (err.st_dev, err.st_ino),
            "rlimits": {name: resource.getrlimit(getattr(resource, name))
                        for name in ("RLIMIT_AS", "RLIMIT_CPU", "RLIMIT_FSIZE", "RLIMIT_CORE", "RLIMIT_NPROC")},
            "home": os.environ.get("HOME"),
            "vm_size_kb": next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmSize")),
        })


class OwnEnvAgent(_Base):
    """Asks for an env of its own module: its code would run in the env process."""

    env_factory = "hostile_agents:make_env"


class EmptyRoadsAgent(_Base):
    """Asks for an easier env: no background traffic."""

    env_kwargs = {"density": "empty"}
