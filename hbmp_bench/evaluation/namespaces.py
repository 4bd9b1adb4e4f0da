"""The namespace sandbox of agents that run their own code: each agent process in bubblewrap (``bwrap``).

An agent process started here (``start_sandboxed``) lives in its own user (unless the evaluator
is root), PID, mount, network, IPC and UTS namespaces:

- **files**: a fresh root holding, read-only, ``/usr`` (and the ``/lib``, ``/bin`` links), the
  dynamic loader's files of ``/etc``, the Python installation and its libraries, this package,
  the folder the agent's module is found in (or its checkpoint file) and what the evaluator names
  in ``RunnerLimits.agent_readable``; writable only a private ``/tmp`` (a tmpfs of
  ``agent_file_mb``) and the folders named in ``RunnerLimits.agent_writable``. Records, provenance,
  leaderboards, the evaluator's home and its fork server's socket are not in that view;
- **processes**: it sees only its own (``/proc`` of its PID namespace); when the episode ends the
  pool kills the namespace's first process, and the kernel kills every process left in it;
- **network**: none (a network namespace with a loopback that is down);
- **environment**: only ``AGENT_ENVIRONMENT`` (locale, time zone, thread counts) and the names in
  ``RunnerLimits.agent_env``; ``HOME`` and ``TMPDIR`` are the private ``/tmp``;
- **user**: run by root, bwrap runs without a user namespace and the agent process switches, before
  it loads the agent, to a uid of its own for this evaluation (``AgentUidLease``: one no account
  and no running process has, held by this evaluation alone), so it shares no uid with another
  evaluation's agents; run by another user, it keeps that user's uid in a user namespace of its own
  that may not create further ones.

``sandbox_problem`` says whether the host can do this (bwrap installed, namespaces allowed), by
starting Python in such a sandbox once. What it does not give: it is no VM (the kernel is
shared); an agent still uses CPU and memory up to its resource limits, and whatever the
evaluator puts in its view it can read.
"""

from __future__ import annotations

import fcntl
import functools
import json
import os
import pwd
import random
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from pathlib import Path

from hbmp_bench.errors import UserError

BWRAP = "bwrap"
"""The bubblewrap executable (looked up on ``PATH``)."""

AGENT_ENVIRONMENT = ("LANG", "LANGUAGE", "TZ", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                     "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS", "PYTHONHASHSEED", "SUMO_HOME")
"""Variables of the evaluator's environment an agent process gets (and every ``LC_*``); anything
else (API tokens, cloud keys, ``PYTHONPATH`` ...) only when named in ``RunnerLimits.agent_env``."""

ETC_FILES = ("/etc/ld.so.cache", "/etc/ld.so.conf", "/etc/ld.so.conf.d", "/etc/localtime", "/etc/alternatives")
"""What of ``/etc`` the sandbox holds: what the dynamic loader and the time zone need."""

UID_BASE = 0x70000000
UID_COUNT = 1 << 16
"""Run by root, each evaluation's agents get a uid in [UID_BASE, UID_BASE + UID_COUNT)."""

EXIT_SIGNAL_BASE = 128
"""bwrap exits with 128 + n when the agent process was killed by signal n."""


class SandboxUnavailable(UserError):
    """This host cannot run an agent in the namespace sandbox (bwrap missing or namespaces refused)."""


def bwrap_path() -> str | None:
    """Where ``BWRAP`` is, None when it is not installed."""
    return shutil.which(BWRAP)


def _top_level_links() -> list[str]:
    """bwrap arguments for ``/bin``, ``/lib`` ...: the same link where the host has a link (a
    merged ``/usr``), else the folder read-only."""
    out: list[str] = []
    for top in ("/bin", "/sbin", "/lib", "/lib32", "/lib64", "/libx32"):
        if os.path.islink(top):
            out += ["--symlink", os.readlink(top), top]
        elif os.path.isdir(top):
            out += ["--ro-bind", top, top]
    return out


def python_paths() -> list[str]:
    """The folders the agent's Python needs read-only: the installation (``sys.base_prefix``,
    ``sys.prefix``, the real executable's) and this package's source folder."""
    import hbmp_bench

    real = Path(os.path.realpath(sys.executable)).parent.parent
    package = Path(hbmp_bench.__file__).resolve().parent
    return _distinct([sys.base_prefix, sys.base_exec_prefix, sys.prefix, sys.exec_prefix, str(real), str(package)])


def mounted_paths(readable: Iterable[str] = ()) -> list[str]:
    """Every path the sandbox shows read-only at its own place: ``python_paths`` and ``readable``."""
    return _distinct([*python_paths(), *readable])


def _distinct(paths: Iterable[str]) -> list[str]:
    """Existing absolute paths, sorted, without those inside another of them or inside ``/usr``."""
    found = sorted({os.path.abspath(p) for p in paths if p and os.path.exists(p)})
    out: list[str] = []
    for path in found:
        if path == "/" or any(path == k or path.startswith(k.rstrip("/") + "/") for k in [*out, "/usr"]):
            continue
        out.append(path)
    return out


def agent_files(spec: str) -> list[str]:
    """What of the agent's own the sandbox must show read-only: a checkpoint file (a ``.pt``
    spec), or the ``sys.path`` folder its ``module:Class`` module is found in (found without
    importing anything). [] for a registered agent."""
    if spec.endswith(".pt"):
        return [os.path.abspath(spec)] if os.path.isfile(spec) else []
    if ":" not in spec:
        return []
    import importlib.machinery

    top = spec.partition(":")[0].split(".")[0]
    entries = [os.path.abspath(p) for p in sys.path if p and os.path.isdir(p)]
    try:
        found = importlib.machinery.PathFinder.find_spec(top, entries)
    except (ImportError, ValueError):
        found = None
    if found is None:
        return []
    places = list(found.submodule_search_locations or []) or ([found.origin] if found.origin else [])
    out = []
    for place in places:
        parent = os.path.dirname(os.path.abspath(place))
        entry = next((e for e in entries if os.path.abspath(e) == parent), parent)
        out.append(entry if entry != "/" else os.path.abspath(place))
    return out


def agent_environment(extra: Sequence[str] = ()) -> dict[str, str]:
    """The agent process's whole environment: ``AGENT_ENVIRONMENT`` and ``LC_*`` from this one,
    the names in ``extra`` (the evaluator's choice), a ``PATH`` of system folders, and ``HOME``
    and ``TMPDIR`` in the sandbox's private ``/tmp``."""
    env = {k: v for k, v in os.environ.items() if k in AGENT_ENVIRONMENT or k.startswith("LC_") or k in extra}
    env.update(PATH="/usr/local/bin:/usr/bin:/bin", HOME="/tmp", TMPDIR="/tmp", USER="agent", LOGNAME="agent",
               PYTHONDONTWRITEBYTECODE="1")
    return env


def bwrap_argv(command: Sequence[str], *, readable: Iterable[str] = (), writable: Iterable[str] = (),
               tmp_mb: int | None = None, as_root: bool | None = None, info_fd: int | None = None) -> list[str]:
    """The bwrap command line that runs ``command`` in the sandbox the module docstring describes.

    Args:
        readable: files and folders shown read-only at their own paths (besides ``python_paths``).
        writable: folders shown writable at their own paths.
        tmp_mb: size of the private ``/tmp`` [MiB] (None: the tmpfs default, half the RAM).
        as_root: whether the evaluator runs as root (default: whether this process does); root
            keeps the capabilities to switch users (``CAP_SETUID``, ``CAP_SETGID``) and to read
            the files it shows (``CAP_DAC_READ_SEARCH``) until the agent process switches to
            its own uid, all others are dropped.
        info_fd: descriptor bwrap writes its JSON information to (the namespace's first pid).
    """
    tool = bwrap_path()
    if tool is None:
        raise SandboxUnavailable(f"{BWRAP} (bubblewrap) is not installed")
    as_root = os.geteuid() == 0 if as_root is None else as_root
    argv = [tool, "--die-with-parent", "--new-session", "--unshare-pid", "--unshare-net", "--unshare-ipc",
            "--unshare-uts", "--unshare-cgroup-try", "--hostname", "sandbox"]
    if as_root:
        argv += ["--cap-drop", "ALL", "--cap-add", "CAP_SETUID", "--cap-add", "CAP_SETGID",
                 "--cap-add", "CAP_DAC_READ_SEARCH"]
    else:
        argv += ["--unshare-user", "--disable-userns"]
    if info_fd is not None:
        argv += ["--info-fd", str(info_fd)]
    argv += ["--proc", "/proc", "--dev", "/dev"]
    if tmp_mb is not None:
        argv += ["--size", str(tmp_mb * 1024 * 1024)]
    argv += ["--tmpfs", "/tmp", "--ro-bind", "/usr", "/usr", *_top_level_links()]
    for path in ETC_FILES:
        if os.path.exists(path):
            argv += ["--ro-bind", path, path]
    shown = mounted_paths(readable)
    for path in shown:
        argv += ["--ro-bind", path, path]
    rw = sorted({os.path.abspath(p) for p in writable if os.path.isdir(p)})
    for path in rw:
        argv += ["--bind", path, path]
    # the folders bwrap made to hold those (private to root, when root runs it) may be searched by anyone
    made = {str(a) for p in [*shown, *rw] for a in Path(p).parents} - {"/", "/tmp", "/usr"}
    # (inside the private /tmp too: a clone or virtualenv under the host's /tmp is shown there)
    made = {m for m in made if not any(m == s or m.startswith(s.rstrip("/") + "/") for s in [*shown, *rw, "/usr"])}
    for path in sorted(made):
        argv += ["--chmod", "0755", path]
    return [*argv, "--chdir", "/tmp", "--", *command]


@functools.lru_cache(maxsize=4)
def _probe(tool: str | None, as_root: bool) -> str:
    if tool is None:
        return f"{BWRAP} (bubblewrap) is not installed (on Debian or Ubuntu: apt-get install bubblewrap)"
    try:
        done = subprocess.run(bwrap_argv([sys.executable, "-s", "-B", "-c", "import encodings"], as_root=as_root),
                              stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=60,
                              env=agent_environment())
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"{tool} could not be run: {exc}"
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        return f"{tool} cannot create the sandbox's namespaces on this host: {last}"
    return ""


def sandbox_problem() -> str:
    """Why this host cannot run agents in the namespace sandbox; "" when it can (checked once
    per process by running Python in it)."""
    return _probe(bwrap_path(), os.geteuid() == 0)


def _uids_in_use() -> set[int]:
    """Real uids of the live processes (from ``/proc``)."""
    used = set()
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/status") as fh:
                for line in fh:
                    if line.startswith("Uid:"):
                        used.add(int(line.split()[1]))
                        break
        except (OSError, ValueError, IndexError):
            continue
    return used


class AgentUidLease:
    """A uid (and the gid of the same number) for one evaluation's agents, held until ``release``.

    Only for an evaluator that runs as root. The uid has no account (``/etc/passwd``), no live
    process runs as it, and no other evaluation holds it: its lock file, in a folder only root
    may write (``<tmp>/hbmp-bench-agent-uids``), is locked while this lease lives.

    Attributes:
        uid / gid: the numbers the agent process switches to.
    """

    def __init__(self, attempts: int = 256):
        if os.geteuid() != 0:
            raise PermissionError("only root can give agents a uid of their own")
        folder = Path(tempfile.gettempdir()) / "hbmp-bench-agent-uids"
        folder.mkdir(mode=0o700, exist_ok=True)
        st = os.lstat(folder)
        if st.st_uid != 0 or not os.path.isdir(folder) or os.path.islink(folder) or st.st_mode & 0o022:
            raise PermissionError(f"{folder} must be a folder of root's that no one else may write")
        used = _uids_in_use()
        for _ in range(attempts):
            uid = UID_BASE + random.randrange(UID_COUNT)
            if uid in used or _has_account(uid):
                continue
            fd = os.open(folder / f"{uid}.lock", os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                continue
            self.uid = self.gid = uid
            self._fd: int | None = fd
            return
        raise RuntimeError(f"no free agent uid in [{UID_BASE}, {UID_BASE + UID_COUNT}) after {attempts} tries")

    def release(self) -> None:
        """Give the uid back (its lock file stays)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __del__(self):
        self.release()


def _has_account(uid: int) -> bool:
    try:
        pwd.getpwuid(uid)
    except KeyError:
        return False
    return True


class SandboxedProcess:
    """An agent process in the sandbox, seen from the pool: the ``bwrap`` process that runs it,
    with the subset of ``multiprocessing.Process`` the pool uses (``pid``, ``exitcode``,
    ``join``, ``is_alive``, ``kill``). ``kill`` ends the whole PID namespace."""

    name = "hbmp-agent"

    def __init__(self, popen: subprocess.Popen, info_r: int):
        self.popen = popen
        self.pid = popen.pid
        self._info_r: int | None = info_r
        self.namespace_pid: int | None = None
        """Host pid of the namespace's first process (bwrap's init): when it is gone, so is every
        process of the namespace."""

    def _read_info(self, timeout_s: float) -> None:
        if self._info_r is None:
            return
        ready, _, _ = select.select([self._info_r], [], [], timeout_s)
        if not ready:
            return
        data = b""
        try:
            while chunk := os.read(self._info_r, 4096):
                data += chunk
                if data.rstrip().endswith(b"}"):
                    break
        except OSError:
            pass
        os.close(self._info_r)
        self._info_r = None
        try:
            self.namespace_pid = int(json.loads(data)["child-pid"])
        except (ValueError, KeyError, TypeError):
            self.namespace_pid = None

    @property
    def exitcode(self) -> int | None:
        """None while it runs; -n when the agent process was killed by signal n (also inside
        the sandbox, which bwrap reports as 128 + n); else its exit status."""
        code = self.popen.poll()
        if code is not None and EXIT_SIGNAL_BASE < code <= EXIT_SIGNAL_BASE + 64:
            return -(code - EXIT_SIGNAL_BASE)
        return code

    def join(self, timeout: float | None = None) -> None:
        try:
            self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            pass

    def is_alive(self) -> bool:
        return self.popen.poll() is None

    def kill(self, wait_s: float = 5.0) -> None:
        """SIGKILL the namespace's first process and bwrap, and wait (at most ``wait_s`` [s])
        until the namespace's first process is gone: the kernel has then ended all of it."""
        self._read_info(0.0 if self.popen.poll() is not None else 1.0)
        for pid in (self.namespace_pid, self.pid):
            if pid is not None:
                try:
                    os.kill(pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass
        self.join(wait_s)
        deadline = time.monotonic() + wait_s
        while self.namespace_pid is not None and _alive(self.namespace_pid) and time.monotonic() < deadline:
            time.sleep(0.005)
        if self._info_r is not None:
            os.close(self._info_r)
            self._info_r = None


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            text = fh.read()
    except OSError:
        return False
    return text[text.rfind(b")") + 2:text.rfind(b")") + 3] not in (b"Z", b"X")


def start_sandboxed(config: dict, pass_fds: Sequence[int], *, readable: Iterable[str], writable: Iterable[str],
                    extra_env: Sequence[str], tmp_mb: int | None) -> SandboxedProcess:
    """Start ``agent_process.sandbox_entry`` with ``config`` in the sandbox, handing it the
    descriptors ``pass_fds`` (its channel and lifeline); stdout goes to this process's stderr."""
    info_r, info_w = os.pipe()
    command = [sys.executable, "-s", "-B", "-c",
               "from hbmp_bench.evaluation.agent_process import sandbox_entry; sandbox_entry()", json.dumps(config)]
    argv = bwrap_argv(command, readable=readable, writable=writable, tmp_mb=tmp_mb, info_fd=info_w)
    try:
        popen = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=2,  # never the evaluator's stdout
                                 pass_fds=(*pass_fds, info_w), env=agent_environment(extra_env), close_fds=True)
    except BaseException:
        os.close(info_r)
        raise
    finally:
        os.close(info_w)
    return SandboxedProcess(popen, info_r)
