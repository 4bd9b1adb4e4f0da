"""The agent sandbox: what an agent process gives up before the agent's code runs, and how the pool ends it.

Agents that bring their own code or data also run in the namespace sandbox (``namespaces``:
bubblewrap), which holds what follows too; this module is all a trusted agent
(``RunnerLimits.trust_agent``, the package's registered agents) gets.

An agent under evaluation is untrusted code. Before its process imports or builds the agent
(``enter_sandbox``), it

1. starts its own session and process group (``os.setsid``), so that the pool ends it together
   with every process it forked (``kill_session``, after every episode); a child that left the
   session is an orphan of the fork server by then (``adopt_orphans``), which the pool kills too
   (``reap_orphans``);
2. closes every file descriptor it inherited except its channel and its lifeline (stdin stays
   ``/dev/null``; stdout becomes a copy of stderr, so the evaluator's own output — a ``--json``
   summary — cannot be forged);
3. cannot gain privileges through ``exec`` of a set-user-id program (``PR_SET_NO_NEW_PRIVS``);
4. gets resource limits it cannot raise (soft = hard, but for CPU time, where the hard limit
   lies 1 s past the soft one, so that the agent first gets SIGXCPU): address space (``RLIMIT_AS``),
   CPU time (``RLIMIT_CPU``), largest file written (``RLIMIT_FSIZE``), no core files, and, under
   its own user, a cap on that user's processes and threads (``RLIMIT_NPROC``);
5. when the evaluator runs as root, switches for good to an unprivileged user
   (``RunnerLimits.agent_user``, default ``nobody``): it can then neither write the caller's
   files (records, leaderboard) nor signal, trace or read the memory of the evaluator's processes.
   It switches *before* loading the agent, so no agent code ever runs as root; ``HOME`` becomes
   the user's (as with ``su``). (An agent whose build runs only the package's code — a registered
   agent, a checkpoint file read as data — is built just before the switch.) Directories on
   ``sys.path`` that the user cannot reach (a Python installed under ``/root``) are opened while
   still root and imported from through ``/proc/self/fd``; a ``module:Class`` agent's own files
   must be readable by that user.

The env process, the pool's process and the fork server make themselves non-dumpable
(``protect_process``): a process of the same user can then neither trace them nor read or write
their memory through ``/proc/<pid>/mem``.

What this does not promise: it is not a container or a VM. Running as your own user (evaluator
not root), the agent can still read and write whatever your user can — the records and
leaderboard files included (the evaluator detects that, see ``integrity``), your home folder and
the installed package — can signal your processes (killing the env process makes a visible
``sim_error``), and can reach the network. With the ``spawn`` start method there is no fork
server to adopt orphans, so a child that starts a session of its own escapes the kill. For
untrusted agents, run the evaluator as root (the agent then runs as ``nobody``) or inside a
container.
"""

from __future__ import annotations

import ctypes
import os
import pwd
import resource
import signal
import stat
import sys
import time
from collections.abc import Callable, Iterable
from typing import Any

from hbmp_bench.errors import ConfigError

PR_SET_DUMPABLE = 4
PR_SET_CHILD_SUBREAPER = 36
PR_SET_NO_NEW_PRIVS = 38

_MIB = 1024 * 1024


class SandboxError(RuntimeError):
    """The agent process could not be confined as configured (the evaluator's problem, not the agent's)."""


def _prctl(option: int, value: int) -> bool:
    """``prctl(option, value)``; False where it failed or does not exist (not Linux)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(option, value, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def protect_process() -> bool:
    """Make this process non-dumpable: no core files, and processes of the same user (not root)
    can neither trace it nor open its ``/proc/<pid>/mem``, ``environ`` or ``fd``. Lasts until
    the process ends; returns False where it is not supported."""
    return _prctl(PR_SET_DUMPABLE, 0)


def adopt_orphans() -> bool:
    """Make this process (the fork server) the reaper of its descendants' orphans: a process an
    agent forked, that outlives the agent, even in a session of its own, becomes a child of this
    process (``reap_orphans`` finds it) instead of init's. False where not supported."""
    return _prctl(PR_SET_CHILD_SUBREAPER, 1)


def agent_account(user: str | None) -> pwd.struct_passwd | None:
    """The account the agent process switches to: ``user``'s when this process runs as root and
    ``user`` is set, else None (the agent keeps the caller's user). Raises ValueError for an
    unknown user."""
    if user is None or os.geteuid() != 0:
        return None
    try:
        account = pwd.getpwnam(user)
    except KeyError:
        raise ConfigError(f"agent_user {user!r} does not exist on this machine: name an unprivileged user "
                         "(the agent process runs as it), or None to run agents as root") from None
    if account.pw_uid == 0:
        raise ConfigError(f"agent_user {user!r} is root: name an unprivileged user, or None to run agents as root")
    return account


def enter_sandbox(limits: Any, keep_fds: Iterable[int], before_switch: Callable[[], None] | None = None,
                  account: Any = None) -> str | None:
    """Confine this (agent) process as the module docstring says, before any agent code runs.

    Args:
        limits: the ``RunnerLimits`` (``agent_memory_mb``, ``agent_cpu_s``, ``agent_file_mb``,
            ``agent_processes``, ``agent_user``).
        keep_fds: descriptors to keep open besides 0, 1 and 2 (the channel, the lifeline).
        before_switch: called once confined but before the user switch (building an agent whose
            build runs only the package's code, from files only the caller can read); called
            whether or not the user is switched.
        account: the account to switch to (``pw_uid``, ``pw_gid``, ``pw_name``, ``pw_dir``), in
            place of ``limits.agent_user``'s: the uid of its own an evaluation run by root gives
            the agents it runs in the namespace sandbox (``namespaces.AgentUidLease``).

    Returns the user the process switched to (None: it kept the caller's). Raises
    ``SandboxError`` when a step that was asked for fails.
    """
    try:
        os.setsid()
    except OSError as exc:  # already a session leader: only if the caller did it
        if os.getsid(0) != os.getpid():
            raise SandboxError(f"setsid failed: {exc}") from None
    sys.stdout.flush()
    os.dup2(2, 1)
    close_inherited_fds(keep_fds)
    _prctl(PR_SET_NO_NEW_PRIVS, 1)
    if account is None:
        account = agent_account(limits.agent_user)
    _set_limit(resource.RLIMIT_CORE, 0)
    if limits.agent_memory_mb is not None:
        _set_limit(resource.RLIMIT_AS, limits.agent_memory_mb * _MIB)
    if limits.agent_cpu_s is not None:  # SIGXCPU at the limit (says why it ended), SIGKILL a second later
        _set_limit(resource.RLIMIT_CPU, limits.agent_cpu_s, limits.agent_cpu_s + 1)
    if limits.agent_file_mb is not None:
        _set_limit(resource.RLIMIT_FSIZE, limits.agent_file_mb * _MIB)
    if before_switch is not None:
        before_switch()
    if account is not None:
        if limits.agent_processes is not None:
            _set_limit(resource.RLIMIT_NPROC, limits.agent_processes)
        reroute_import_paths(account.pw_uid, account.pw_gid)
        switch_user(account)
        return account.pw_name
    return None


def _set_limit(kind: int, value: int, hard: int | None = None) -> None:
    """Set the soft limit to ``value`` and the hard one to ``hard`` (default ``value``), never
    above an existing hard limit."""
    hard = value if hard is None else hard
    _, current = resource.getrlimit(kind)
    if current != resource.RLIM_INFINITY:
        value, hard = min(value, current), min(hard, current)
    try:
        resource.setrlimit(kind, (value, hard))
    except (ValueError, OSError) as exc:
        raise SandboxError(f"cannot set resource limit {kind} to {value}: {exc}") from None


USER_DIRS = ("XDG_DATA_HOME", "XDG_CONFIG_HOME", "XDG_CACHE_HOME", "XDG_STATE_HOME", "XDG_RUNTIME_DIR", "TMPDIR")
"""Environment variables naming per-user folders: dropped when the agent's user cannot reach them."""


def switch_user(account: Any) -> None:
    """Become ``account`` (a ``pwd.struct_passwd`` or an object with its ``pw_uid``, ``pw_gid``,
    ``pw_name`` and ``pw_dir``: its uid and primary gid, no supplementary groups) for good, and check
    that root cannot be regained. ``HOME``, ``USER`` and ``LOGNAME`` become the account's (as
    ``su`` does); ``USER_DIRS`` variables it cannot reach are removed."""
    os.environ.update(HOME=account.pw_dir, USER=account.pw_name, LOGNAME=account.pw_name)
    for name in USER_DIRS:
        if name in os.environ and not _can_search(os.environ[name], account.pw_uid, account.pw_gid):
            del os.environ[name]
    try:
        os.setgroups([])
        os.setresgid(account.pw_gid, account.pw_gid, account.pw_gid)
        os.setresuid(account.pw_uid, account.pw_uid, account.pw_uid)
    except OSError as exc:
        raise SandboxError(f"cannot switch the agent process to user {account.pw_name!r}: {exc}") from None
    try:
        os.setuid(0)
    except PermissionError:
        return
    raise SandboxError(f"the agent process could regain root after switching to {account.pw_name!r}")


def close_inherited_fds(keep: Iterable[int]) -> list[int]:
    """Close every open descriptor above 2 not in ``keep``; returns the ones closed.

    The fork server hands its children the descriptors multiprocessing uses to talk to it and to
    its resource tracker; nothing in the agent process needs them, so their Python owners are
    told they are gone.
    """
    keep = {0, 1, 2, *keep}
    try:
        open_fds = sorted(int(name) for name in os.listdir("/proc/self/fd"))
    except OSError:
        open_fds = list(range(3, 256))
    closed = []
    for fd in open_fds:
        if fd in keep:
            continue
        try:
            os.close(fd)
        except OSError:
            continue
        closed.append(fd)
    _forget_multiprocessing_fds()
    return closed


def _forget_multiprocessing_fds() -> None:
    from multiprocessing import forkserver, process, resource_tracker

    tracker = getattr(resource_tracker, "_resource_tracker", None)
    if tracker is not None and hasattr(tracker, "_fd"):
        tracker._fd = None
        if hasattr(tracker, "_pid"):
            tracker._pid = None
    server = getattr(forkserver, "_forkserver", None)
    if server is not None:
        if hasattr(server, "_forkserver_alive_fd"):
            server._forkserver_alive_fd = None
        if hasattr(server, "_inherited_fds"):
            server._inherited_fds = None
    if hasattr(process, "_parent_process"):
        process._parent_process = None


def _can_search(path: str, uid: int, gid: int) -> bool:
    """Whether ``uid``/``gid`` (no supplementary groups) may search every directory from ``/`` to ``path``."""
    parts = [p for p in os.path.abspath(path).split(os.sep) if p]
    for k in range(len(parts) + 1):
        try:
            st = os.stat(os.sep + os.sep.join(parts[:k]))
        except OSError:
            return False
        bit = stat.S_IXUSR if st.st_uid == uid else stat.S_IXGRP if st.st_gid == gid else stat.S_IXOTH
        if not st.st_mode & bit:
            return False
    return True


def reroute_import_paths(uid: int, gid: int) -> dict[str, str]:
    """Make the import paths this process uses reachable for ``uid``/``gid`` before switching to them.

    Each ``sys.path`` directory the user cannot reach is opened now and replaced by
    ``/proc/self/fd/<n>``, which the process can always follow; ``__path__`` of packages already
    imported from there are rewritten too. Returns the replaced paths (old → new).
    """
    moved: dict[str, str] = {}
    for entry in list(sys.path):
        if not entry or entry in moved or not os.path.isdir(entry) or _can_search(entry, uid, gid):
            continue
        try:
            fd = os.open(entry, os.O_RDONLY | os.O_DIRECTORY)
        except OSError:
            continue
        moved[os.path.abspath(entry)] = f"/proc/self/fd/{fd}"
    if not moved:
        return moved

    def new_path(path: str) -> str:
        full = os.path.abspath(path)
        for old, new in moved.items():
            if full == old or full.startswith(old + os.sep):
                return new + full[len(old):]
        return path

    sys.path[:] = [new_path(p) if p else p for p in sys.path]
    for module in list(sys.modules.values()):
        search = getattr(module, "__path__", None)
        if isinstance(search, list):
            search[:] = [new_path(p) for p in search]
    sys.path_importer_cache.clear()
    import importlib

    importlib.invalidate_caches()
    return moved


def _stat_fields(pid: int | str) -> list[str]:
    """Fields of ``/proc/<pid>/stat`` after the command name (state, ppid, pgrp, session, ...); [] if gone."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as fh:
            text = fh.read().decode("ascii", errors="replace")
    except OSError:
        return []
    return text[text.rfind(")") + 2:].split()


def parent_pid(pid: int) -> int | None:
    """The parent of ``pid`` (from ``/proc``), None where unknown."""
    fields = _stat_fields(pid)
    return int(fields[1]) if len(fields) > 1 else None


def _live_pids() -> list[int]:
    try:
        return [int(name) for name in os.listdir("/proc") if name.isdigit()]
    except OSError:
        return []


def reap_orphans(parent: int, keep: Iterable[int], rounds: int = 20) -> int:
    """SIGKILL every live child of ``parent`` (the fork server, see ``adopt_orphans``) that is
    outside ``parent``'s session and not in ``keep`` (the running agent processes), until none is
    left; returns how many were found.

    Whatever an agent forked ends up here once its own parent is gone. The session tells it from
    the fork server's own children (env processes, other users of the fork server): those share
    its session, while an agent and all it forks live in the agent's session or in sessions of
    their own, and no process can join another session.
    """
    keep = set(keep)
    home = _stat_fields(parent)
    if len(home) < 4:
        return 0

    def strays() -> list[int]:
        return [pid for pid in _live_pids()
                if (f := _stat_fields(pid)) and len(f) > 3 and f[0] != "Z" and f[1] == str(parent)
                and f[3] != home[3] and pid not in keep]

    return _kill_until_gone(strays, rounds)


def session_members(sid: int) -> list[int]:
    """Live processes (not zombies) of session ``sid``, from ``/proc``; [] where there is no ``/proc``."""
    members = []
    for pid in _live_pids():
        fields = _stat_fields(pid)
        if len(fields) > 3 and fields[0] != "Z" and fields[3] == str(sid):
            members.append(pid)
    return members


def kill_session(sid: int, rounds: int = 20) -> int:
    """SIGKILL the process group ``sid`` and every process of session ``sid`` (an agent process
    and whatever it forked, also into other groups), until none is left. Returns how many
    processes were found alive in the session."""
    def members() -> list[int]:
        try:
            os.killpg(sid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        return [pid for pid in session_members(sid) if pid != os.getpid()]

    return _kill_until_gone(members, rounds)


def _kill_until_gone(find: Callable[[], list[int]], rounds: int) -> int:
    """SIGKILL what ``find()`` lists until it lists nothing (at most ``rounds`` times); returns how
    many processes were found alive in all."""
    found = 0
    for _ in range(rounds):
        pids = find()
        if not pids:
            return found
        found += len(pids)
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
        time.sleep(0.01)
    return found
