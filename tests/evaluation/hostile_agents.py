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


TEST_VARIABLES = ("HBMP_TEST_AGENT_DIR", "HBMP_TEST_RECORDS", "HBMP_TEST_BOARD")
"""Variables the tests hand the hostile agents (the sandbox passes only those it is told to)."""


def for_tests(limits=None, **changes):
    """``limits`` (default ``RunnerLimits()``) with ``changes``, letting the hostile agents see
    ``TEST_VARIABLES`` and write to ``HBMP_TEST_AGENT_DIR`` (where they report) in the sandbox."""
    import dataclasses

    from hbmp_bench.evaluation import RunnerLimits

    limits = dataclasses.replace(limits or RunnerLimits(), **changes)
    folder = os.environ.get("HBMP_TEST_AGENT_DIR")
    writable = (*limits.agent_writable, folder) if folder and folder not in limits.agent_writable else limits.agent_writable
    return dataclasses.replace(limits, agent_env=tuple(dict.fromkeys((*limits.agent_env, *TEST_VARIABLES))),
                               agent_writable=writable)


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
        if not lines:
            return "no record to copy yet"
        town, task, index = self.key.split("/")
        template = json.loads(lines[-1])
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
        except OSError:  # EPERM; EINVAL in a user namespace where uid 0 is not mapped
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


# ---------------------------------------------------------------- attacks on the verdict (issue 41, part A)


class PreForgingAgent(_Base):
    """Finding 2: at construction, before the evaluator could note its records file, writes a
    complete, all-success records file for its episodes and its provenance side file (with the
    right code fingerprint) to ``HBMP_TEST_RECORDS``, then stands still, hoping it is resumed."""

    def __init__(self):
        super().__init__()
        path = os.environ.get("HBMP_TEST_RECORDS")
        if not path:
            return
        from hbmp_bench.evaluation.evaluate import code_fingerprint
        from hbmp_bench.scenarios import suite_episodes

        outcome = {}
        records = Path(path)
        lines = []
        for k, episode in enumerate(suite_episodes("corl2017", "Town01", "Straight")[:2]):
            lines.append(json.dumps({
                "suite": "corl2017", "town": "Town01", "task": "Straight", "episode": k, "seed": episode.seed,
                "agent": "hostile_agents:PreForgingAgent", "package_version": "0.1.0", "fidelity": "event",
                "success": True, "route_completion": 1.0, "collision_vehicle": 0, "collision_pedestrian": 0,
                "collision_other": 0, "wrong_lane": 0, "off_road": 0, "red_light": 0, "timeout": False,
                "duration_s": 10.0, "distance_m": episode.route_length_m, "route_length_m": episode.route_length_m,
                "decisions": 10, "driving_score": 100.0, "end_reason": "goal"}) + "\n")
        side = records.with_name(records.name + ".provenance.json")
        try:
            records.write_text("".join(lines))
            side.write_text(json.dumps({"code": code_fingerprint(), "agent": "", "maps": {}}))
            outcome["records"] = "written"
        except OSError as exc:
            outcome["records"] = f"write denied: {type(exc).__name__}"
        report(type(self).__name__, outcome)


def _chain(marker: str, rounds: int) -> None:
    """A process chain that re-forks every millisecond (each parent exits once its child runs),
    each link in a session of its own; the last one leaves ``marker``."""
    for _ in range(rounds):
        try:
            os.setsid()
        except OSError:
            pass
        if os.fork() != 0:
            os._exit(0)
        time.sleep(0.001)
    Path(os.environ["HBMP_TEST_AGENT_DIR"], marker).write_text(str(os.getpid()))
    os._exit(0)


class ForkChainAgent(_Base):
    """Finding 5: five chains that re-fork every millisecond (an orphan hunt that stops at the
    first empty scan misses them); each would leave ``chain-<k>`` after about 2 s."""

    def attack(self):
        for k in range(5):
            if os.fork() == 0:
                _chain(f"chain-{k}", 2000)
        report(type(self).__name__, {"chains": 5})


class ForkServerAgent(_Base):
    """Finding 5: looks for the evaluator's fork-server socket (``/tmp/pymp-*/listener-*``) and
    asks it to fork, as an agent of the evaluator's user could."""

    def attack(self):
        import glob

        found = glob.glob("/tmp/pymp-*/listener-*")
        outcome = {"sockets": found}
        for path in found:
            try:
                with socket.socket(socket.AF_UNIX) as sock:
                    sock.settimeout(1.0)
                    sock.connect(path)
                    outcome[path] = "connected"
            except OSError as exc:
                outcome[path] = f"denied: {type(exc).__name__}"
        report(type(self).__name__, outcome)


class UidAgent(_Base):
    """Reports its uid (the tests compare two evaluations')."""

    def attack(self):
        report(f"{type(self).__name__}-{os.getuid()}", {"uid": os.getuid()})
        time.sleep(1.0)  # so the two evaluations' agents overlap


class SnoopingAgent(_Base):
    """Findings 9 and 5: reads its environment (API tokens), opens connections (to the host's
    loopback, where the test listens, to the internet, to an abstract Unix socket of the host)
    and lists the processes it can see."""

    def attack(self):
        outcome = {"environ": sorted(os.environ), "secret": os.environ.get("HBMP_FAKE_API_TOKEN", "")}
        port = int(os.environ.get("HBMP_TEST_PORT", "0") or 0)
        targets = {"loopback": (socket.AF_INET, ("127.0.0.1", port)), "internet": (socket.AF_INET, ("1.1.1.1", 80)),
                   "abstract": (socket.AF_UNIX, "\0" + os.environ.get("HBMP_TEST_ABSTRACT", "hbmp-test"))}
        for name, (family, address) in targets.items():
            try:
                with socket.socket(family, socket.SOCK_STREAM) as sock:
                    sock.settimeout(1.0)
                    sock.connect(address)
                    outcome[name] = "connected"
            except OSError as exc:
                outcome[name] = f"failed: {type(exc).__name__}: {exc}"
        outcome["processes"] = sorted(int(p) for p in os.listdir("/proc") if p.isdigit())
        report(type(self).__name__, outcome)


class PycPoisonerAgent(_Base):
    """Finding 7: writes bytecode for a package module (``hbmp_bench/metrics/episode.py``) that
    would run its own code in the next process importing it, both in the module's
    ``__pycache__`` and as a fresh ``__pycache__`` folder of the package."""

    def attack(self):
        import importlib.util
        import marshal

        import hbmp_bench.metrics.episode as target

        payload = compile("import pathlib, os; pathlib.Path(os.environ.get('HBMP_TEST_AGENT_DIR', '/tmp'), "
                          "'pwned-pyc').write_text('x')", target.__file__, "exec")
        cached = importlib.util.cache_from_source(target.__file__)
        st = os.stat(target.__file__)
        data = importlib.util.MAGIC_NUMBER + struct.pack("<III", 0, int(st.st_mtime) & 0xFFFFFFFF,
                                                         st.st_size & 0xFFFFFFFF) + marshal.dumps(payload)
        outcome = {}
        for name, path in {"pycache": cached, "beside": target.__file__ + "c"}.items():
            try:
                os.makedirs(os.path.dirname(path), exist_ok=True)
                with open(path + ".hbmp-test", "xb") as fh:  # never the live name: a test must not poison a tree
                    fh.write(data)
                outcome[name] = f"written: {path}.hbmp-test"
            except OSError as exc:
                outcome[name] = f"denied: {type(exc).__name__}"
        report(type(self).__name__, outcome)


class SlowAgent(_Base):
    """Finding 8: takes just under the decision timeout at every decision (``HBMP_TEST_SLOW_S``)."""

    def act(self, observation, info):
        time.sleep(float(os.environ.get("HBMP_TEST_SLOW_S", "2.0")))
        return KEEP


class HomeReaderAgent(_Base):
    """Reads what it can of the evaluator's home and of the records key the seals use."""

    def attack(self):
        import pwd as pwd_module

        outcome = {}
        home = os.environ.get("HBMP_TEST_EVALUATOR_HOME") or pwd_module.getpwuid(0).pw_dir
        for path in (home, os.path.join(home, ".config", "hbmp-bench", "records.key"), "/etc/shadow"):
            try:
                if os.path.isdir(path):
                    outcome[path] = f"listed {len(os.listdir(path))}"
                else:
                    outcome[path] = f"read {len(open(path, 'rb').read())} bytes"
            except OSError as exc:
                outcome[path] = f"denied: {type(exc).__name__}"
        report(type(self).__name__, outcome)
