"""A pool of isolated episode slots: per slot one env process, and one fresh agent process per episode.

The pool (in the calling process) owns every child. Each slot has an env process, which holds
the SUMO simulation (libsumo: one per process) across episodes. For every episode the pool
starts a new agent process and hands the env process its end of a fresh channel (a socket pair);
the agent sees the observations and infos the env process sends, nothing else, and enters the
sandbox (``sandbox``) before any agent code runs. When the episode ends the pool kills the agent
process with its whole session (whatever it forked), before the outcome is yielded. The pool
hands out one episode at a time per slot, watches heartbeats, and

- records an ``agent_error`` episode when the agent raises, hangs past ``decision_timeout_s``,
  dies, or breaks the channel's protocol (its exit status is added to the error);
- kills a slot whose env process sends no heartbeat for ``watchdog_s`` (``start_timeout_s``
  right after it starts) or dies, and retries that episode up to ``retries`` times before
  recording a ``sim_error``; the record it ends with names every earlier attempt (``RETRIED``);
- records an ``agent_error``, not retried, when the env process died or stalled while the agent
  had the turn (the simulator idle, waiting for its answer): an agent that kills or stops it.

Outcomes are yielded as episodes finish, so a caller can append each record at once.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import os
import signal
import socket
import sys
import time
from collections import deque
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from multiprocessing import reduction
from multiprocessing.connection import Connection, wait

from hbmp_bench.errors import ConfigError, UserError
from hbmp_bench.evaluation import channel
from hbmp_bench.evaluation.agent_process import agent_main
from hbmp_bench.evaluation.namespaces import (AgentUidLease, SandboxedProcess, SandboxUnavailable, agent_files,
                                              mounted_paths, sandbox_problem, start_sandboxed)
from hbmp_bench.evaluation.env_process import blank_records, env_main
from hbmp_bench.evaluation.sandbox import agent_account, kill_session, protect_process, reap_orphans
from hbmp_bench.evaluation.tasks import EpisodeTask, RunnerLimits, with_agent_env
from hbmp_bench.metrics.records import AGENT_ERROR, SIM_ERROR, EpisodeRecord

RETRIED = "retried"
"""How the note on a record of an episode that took more than one attempt begins (in its ``error``)."""

POLL_S = 0.2
"""How often the pool checks watchdogs while no message arrives [s]."""

PRELOAD = ("hbmp_bench.evaluation.forkserver_guard", "hbmp_bench.evaluation.env_process",
           "hbmp_bench.evaluation.agent_process", "hbmp_bench.envs.behavior_env", "hbmp_bench.agents",
           "sumolib", "hbmp_bench.planning.rollout")
"""Modules the fork server imports once, so a slot (re)starts in a fraction of a second.
``forkserver_guard`` makes the fork server non-dumpable. Only trusted modules: never the agent's.
The heavy ones an episode needs are named on purpose, as the package imports them where they are
used: libsumo (with ``behavior_env``), sumolib (the road network) and numba (the planner's
roll-out)."""
LEARNED_PRELOAD = ("torch", "tensordict", "hbmp_bench.policies.checkpoints")
"""Added to ``PRELOAD`` for learned agents (registered ones and ``.pt`` checkpoints), so the agent
process each episode starts does not import torch again (seconds); ``torch`` alone for
``module:Class`` agents."""


def preload_for(agent: str | None, limits: RunnerLimits) -> tuple[str, ...]:
    """The fork server's preload list for evaluating ``agent``: ``PRELOAD``, what learned or
    plug-in agents commonly import, and ``limits.agent_preload`` (the evaluator's choice)."""
    from hbmp_bench.agents.learned import TRAIN_COMMANDS

    extra: tuple[str, ...] = ()
    if agent is not None and (agent.endswith(".pt") or agent in TRAIN_COMMANDS):
        extra = LEARNED_PRELOAD
    elif agent is not None and ":" in agent:
        extra = ("torch",)
    return tuple(dict.fromkeys((*PRELOAD, *extra, *limits.agent_preload)))


_LIVE: set[int] = set()
"""Env and agent processes of every pool of this process that are running (never reaped as orphans)."""


def default_start_method() -> str:
    """``forkserver`` where available (fast restarts, children share no state with the caller), else ``spawn``."""
    return "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"


def sandbox_context(start_method: str | None, limits: RunnerLimits, agent: str | None = None):
    """The multiprocessing context agent and env processes start from (its fork server, when
    this call starts it, preloads ``preload_for(agent, limits)``).

    Checks ``limits.agent_user`` (ValueError for an unknown user when root) and makes this
    process non-dumpable, so an agent process of the same user can neither trace it nor read
    its memory (see ``sandbox.protect_process``).
    """
    start_method = start_method or default_start_method()
    if start_method not in ("forkserver", "spawn"):
        raise ConfigError(f"start_method must be 'forkserver' or 'spawn', got {start_method!r}")
    agent_account(limits.agent_user)
    protect_process()
    ctx = mp.get_context(start_method)
    if start_method == "forkserver":
        ctx.set_forkserver_preload(list(preload_for(agent, limits)))
    return ctx


SANDBOX = "sandbox"
FORKED = "forked"
"""How an agent process is isolated: in the namespace sandbox (``namespaces``: a fresh
interpreter in bubblewrap), or forked by the fork server and confined by ``sandbox`` alone."""


def isolation(agent: str, limits: RunnerLimits) -> str:
    """``SANDBOX`` or ``FORKED`` for ``agent``'s processes.

    An agent that brings its own code or data (``module:Class``, a checkpoint file) runs in the
    namespace sandbox, unless ``limits.trust_agent``; the package's registered agents (its own
    code and shipped checkpoints) are forked, which keeps their start fast. Raises
    ``SandboxUnavailable`` for an agent that needs the sandbox on a host that cannot give it,
    saying why and what to do.
    """
    from hbmp_bench.agents import AGENTS

    if limits.trust_agent or agent in AGENTS:
        return FORKED
    problem = sandbox_problem()
    if problem:
        raise SandboxUnavailable(
            f"agent {agent!r} brings its own code or data, and untrusted agents run only in the namespace sandbox, "
            f"which this host cannot give: {problem}. Install bubblewrap (and allow user namespaces, or run the "
            "evaluator as root), or, only for an agent you trust, pass --trust-agent (RunnerLimits(trust_agent=True)):"
            " it then runs as the evaluator's user (as root: as --agent-user) and can read and write what that "
            "user can")
    return SANDBOX


def agent_sys_path(mounted: list[str]) -> list[str]:
    """The entries of this process's ``sys.path`` inside one of the ``mounted`` paths (the
    agent process's ``sys.path`` in the sandbox)."""
    out = []
    for entry in sys.path:
        full = os.path.abspath(entry) if entry else ""
        if full and any(full == m or full.startswith(m.rstrip("/") + "/") for m in mounted) and full not in out:
            out.append(full)
    return out


def start_agent(ctx, agent: str, sock: socket.socket, life_r: Connection, limits: RunnerLimits,
                lease: AgentUidLease | None = None, scene: bool = False):
    """Start an agent process for ``agent`` on its end ``sock`` of a channel (closed here once
    passed): in the namespace sandbox (``isolation``; as uid ``lease`` when the evaluator is
    root), or forked by ``ctx``'s fork server. ``scene``: it drives a scene (every vehicle's
    action in one reply, ``agents.scene.SceneAgent``)."""
    try:
        if isolation(agent, limits) == SANDBOX:
            load = os.path.abspath(agent) if agent.endswith(".pt") else agent
            readable = [*agent_files(agent), *limits.agent_readable]
            config = {"spec": agent, "load": load, "sys_path": agent_sys_path(mounted_paths(readable)),
                      "channel": sock.fileno(), "lifeline": life_r.fileno(),
                      "limits": {k: getattr(limits, k) for k in AGENT_LIMITS},
                      "account": None if lease is None else [lease.uid, lease.gid], "scene": scene}
            return start_sandboxed(config, (sock.fileno(), life_r.fileno()), readable=readable,
                                   writable=limits.agent_writable, extra_env=limits.agent_env,
                                   tmp_mb=limits.agent_file_mb)
        proc = ctx.Process(target=agent_main, args=(sock, agent, life_r, limits, dict(os.environ)),
                           kwargs={"scene": scene}, name="hbmp-agent")
        proc.start()
    finally:
        sock.close()
    _LIVE.add(proc.pid)
    return proc


AGENT_LIMITS = ("agent_memory_mb", "agent_cpu_s", "agent_file_mb", "agent_processes")
"""The ``RunnerLimits`` the agent process applies to itself (``sandbox.enter_sandbox``)."""


def uid_lease_for(agent: str, limits: RunnerLimits) -> AgentUidLease | None:
    """A uid of its own for ``agent``'s sandboxed processes when this process is root, else None."""
    if os.geteuid() != 0 or isolation(agent, limits) != SANDBOX:
        return None
    return AgentUidLease()


def fork_server_pid() -> int | None:
    """The pid of this process's multiprocessing fork server, None while it has none."""
    from multiprocessing import forkserver

    return getattr(getattr(forkserver, "_forkserver", None), "_forkserver_pid", None)


def end_agent(proc, wait_s: float = 0.0) -> int | None:
    """Kill agent process ``proc`` with its whole session, and every orphan its descendants left
    with the fork server (``sandbox.reap_orphans``); returns its exit code from before the kill
    (None when it was still running after ``wait_s`` [s])."""
    proc.join(wait_s)
    code = proc.exitcode
    if isinstance(proc, SandboxedProcess):  # its PID namespace ends with it
        proc.kill()
        return code
    kill_session(proc.pid)
    proc.join(1.0)
    if proc.is_alive():  # killed before it had a session of its own
        proc.kill()
        proc.join(5.0)
    _LIVE.discard(proc.pid)
    server = fork_server_pid()
    if server is not None and server != os.getpid():
        reap_orphans(server, _LIVE)
    return code


def exit_note(code: int | None, limits: RunnerLimits) -> str:
    """How an agent process ended, in words (limits named where one ended it); "" while it ran."""
    if code is None:
        return ""
    if code >= 0:
        return f"agent process exited with code {code}"
    try:
        name = signal.Signals(-code).name
    except ValueError:
        name = f"signal {-code}"
    cause = {
        "SIGXCPU": f": it used up its CPU time limit of {limits.agent_cpu_s} s",
        "SIGXFSZ": f": it wrote past its file size limit of {limits.agent_file_mb} MiB",
        "SIGKILL": " (out of memory, past its CPU time limit, or killed by another process)",
    }.get(name, "")
    return f"agent process killed by {name}{cause}"


def describe_agent(agent: str, limits: RunnerLimits | None = None, start_method: str | None = None
                   ) -> channel.AgentDescription:
    """Build ``agent`` once in a sandboxed agent process and return what it says about itself
    (its env needs and fingerprint), so a bad name fails before any episode and no agent code
    runs in the caller. Raises ``AgentBuildError`` with the agent's error otherwise."""
    limits = limits or RunnerLimits()
    ctx = sandbox_context(start_method, limits, agent)
    lease = uid_lease_for(agent, limits)
    try:
        return _describe(ctx, agent, limits, lease)
    finally:
        if lease is not None:
            lease.release()


def _describe(ctx, agent: str, limits: RunnerLimits, lease: AgentUidLease | None) -> channel.AgentDescription:
    env_sock, agent_sock = socket.socketpair()
    life_r, life_w = ctx.Pipe(duplex=False)
    proc = start_agent(ctx, agent, agent_sock, life_r, limits, lease)
    life_r.close()
    end = channel.EnvEnd(env_sock)
    code = None
    try:
        reply = end.reply(limits.agent_start_timeout_s)
    except channel.ChannelTimeout:
        raise AgentBuildError(f"agent {agent!r} was not built within {limits.agent_start_timeout_s:g} s") from None
    except (channel.ChannelClosed, channel.ProtocolError) as exc:
        code = end_agent(proc, 1.0)
        raise AgentBuildError(f"agent {agent!r} could not be built: {exc}; {exit_note(code, limits) or 'it hung up'}"
                              ) from None
    finally:
        end.close()
        life_w.close()
        if code is None:
            end_agent(proc)
    if reply.kind == channel.ERROR:
        raise AgentBuildError(reply.value)
    if reply.kind != channel.READY:
        raise AgentBuildError(f"agent {agent!r} broke the channel protocol: sent {reply.kind!r} before being ready")
    return reply.value


class AgentBuildError(UserError):
    """The agent cannot be built (bad name, import error, broken constructor) in its own process."""


@dataclass(frozen=True)
class EpisodeOutcome:
    """A finished episode: its records (one per vehicle of its task, ``EpisodeTask.vehicles``: one for a
    single-ego episode, N for a scene), how many attempts it took, and the agent's decision times [s]
    (round trip through the channel; 0 when no decision was made)."""

    records: tuple[EpisodeRecord, ...]
    attempts: int
    max_decision_s: float
    mean_decision_s: float

    @property
    def record(self) -> EpisodeRecord:
        """The record of a single-ego episode (a scene's first vehicle's, ``ego``)."""
        return self.records[0]


class _Slot:
    """An env process (started on first use, restarted after simulation failures) and the agent
    process of the episode it runs."""

    def __init__(self, ctx, limits: RunnerLimits, leases: dict | None = None):
        self.ctx, self.limits = ctx, limits
        self.leases = {} if leases is None else leases
        """The pool's uid leases by agent (``uid_lease_for``), shared by its slots."""
        self.env_proc = self.agent_proc = None
        self.conn: Connection | None = None
        self.lifeline: Connection | None = None
        self.life_r: Connection | None = None
        self.task: EpisodeTask | None = None
        self.turn = None
        self.last_seen = 0.0
        self.heard_from = False

    @property
    def alive(self) -> bool:
        return self.env_proc is not None

    def start(self) -> None:
        pool_end, env_pool_end = self.ctx.Pipe(duplex=True)
        self.life_r, self.lifeline = self.ctx.Pipe(duplex=False)
        environ = dict(os.environ)  # a fork server's children would otherwise see its start-time environment
        self.turn = self.ctx.Value("b", 0, lock=False)  # 1 while the agent has the turn (see env_process._AgentLink)
        self.env_proc = self.ctx.Process(target=env_main, args=(env_pool_end, self.limits, self.life_r, environ,
                                                                self.turn), name="hbmp-env")
        self.env_proc.start()
        _LIVE.add(self.env_proc.pid)
        self.heard_from = False
        env_pool_end.close()
        self.conn = pool_end

    def run(self, task: EpisodeTask, env: RunnerLimits) -> None:
        """Start the episode's agent process and hand the env process the task, the env to run it
        in (``env.env_factory`` and ``env.env_kwargs``) and the agent's channel end (a dead env
        process shows as EOF on ``conn``)."""
        if not self.alive:
            self.start()
        self.task = task
        self.last_seen = time.monotonic()
        env_sock, agent_sock = socket.socketpair()
        try:
            if task.agent not in self.leases:
                self.leases[task.agent] = uid_lease_for(task.agent, self.limits)
            self.agent_proc = start_agent(self.ctx, task.agent, agent_sock, self.life_r, self.limits,
                                          self.leases[task.agent], scene=task.scene)
            self.conn.send(("run", (task, env.env_factory, env.env_kwargs)))
            reduction.send_handle(self.conn, env_sock.fileno(), self.env_proc.pid)
        except OSError:
            pass
        finally:
            env_sock.close()

    def end_agent(self, wait_s: float = 0.0) -> int | None:
        """Kill the episode's agent process and its session; its exit code from before (see ``end_agent``)."""
        proc, self.agent_proc = self.agent_proc, None
        return None if proc is None else end_agent(proc, wait_s)

    def stop(self, graceful: bool = True) -> None:
        """End the agent's session and the env process (a polite stop first when ``graceful``, then kill)."""
        self.end_agent()
        if self.conn is not None:
            if graceful:
                try:
                    self.conn.send(("stop", None))
                except (OSError, BrokenPipeError):
                    pass
            self.conn.close()
        for end in (self.lifeline, self.life_r):
            if end is not None:
                end.close()  # the children exit on the lifeline's EOF
        if self.env_proc is not None:
            self.env_proc.join(1.0 if graceful else 0.0)
            if self.env_proc.is_alive():
                self.env_proc.kill()
                self.env_proc.join(5.0)
            _LIVE.discard(self.env_proc.pid)
        self.env_proc = self.conn = self.lifeline = self.life_r = None
        self.task = None

    def agents_turn(self) -> bool:
        """Whether the env process was waiting for the agent's answer (read from the shared byte)."""
        return self.turn is not None and self.turn.value == 1

    def silent_for(self, now: float) -> float | None:
        """The allowance [s] this slot has gone past without a message, or None while within it."""
        allowance = self.limits.watchdog_s if self.heard_from else self.limits.start_timeout_s
        late = now - self.last_seen - allowance
        return allowance if late > 0 else None

    def exit_codes(self) -> str:
        """How the slot's processes ended (waits briefly for them to be reaped)."""
        procs = [p for p in (self.env_proc, self.agent_proc) if p is not None]
        for proc in procs:
            proc.join(0.5)
        return ", ".join(f"{p.name} exit code {p.exitcode}" for p in procs)


class EpisodePool:
    """Isolated slots that run episodes; use as a context manager (``close`` ends every child).

    Creating a pool makes the calling process non-dumpable for the rest of its life (see
    ``sandbox_context``).

    Each agent's episodes run in the env it asks for (``tasks.with_agent_env``: the flat
    baseline's control env, a learned agent's observation options, the expert's privileged
    fields). The pool learns what an agent asks for by building it once in a sandboxed agent
    process (``describe_agent``) before its first episode, unless ``descriptions`` says it; an
    agent that cannot be built runs in ``limits``' env and fails as ``agent_error`` where it runs,
    one that asks for an env it may not have gets ``agent_error`` records without running.

    Args:
        workers: number of slots (each an env process, plus an agent process per episode).
        limits: timeouts, watchdog, retries and the agent sandbox's limits; its ``env_factory``
            and ``env_kwargs`` win over what agents ask for.
        start_method: multiprocessing start method (default ``default_start_method()``); never
            ``fork``, which would copy the caller's threads and simulation state.
        descriptions: agents already described (by name), e.g. by ``evaluate``, which builds
            the agent first to check it.
    """

    def __init__(self, workers: int = 1, limits: RunnerLimits | None = None, start_method: str | None = None,
                 descriptions: Mapping[str, channel.AgentDescription] | None = None):
        if workers <= 0:
            raise ConfigError(f"workers must be > 0, got {workers}")
        self.workers = workers
        self.limits = limits or RunnerLimits()
        self.ctx = sandbox_context(start_method, self.limits)
        self._slots: list[_Slot] = []
        self._leases: dict[str, AgentUidLease | None] = {}
        self._failed_attempts: dict[EpisodeTask, list[str]] = {}
        self._envs: dict[str, RunnerLimits | str] = {}
        for agent, description in (descriptions or {}).items():
            self._envs[agent] = self._env_of(description)

    def _env_of(self, description: channel.AgentDescription) -> RunnerLimits | str:
        try:
            return with_agent_env(self.limits, description)
        except ValueError as exc:
            return str(exc)

    def agent_env(self, agent: str) -> RunnerLimits | str:
        """``limits`` with the env ``agent``'s episodes run in, or why they cannot run (a message)."""
        if agent not in self._envs:
            try:
                self._envs[agent] = self._env_of(describe_agent(agent, self.limits, self.ctx.get_start_method()))
            except AgentBuildError:
                self._envs[agent] = self.limits
        return self._envs[agent]

    def __enter__(self) -> "EpisodePool":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        for slot in self._slots:
            slot.stop(graceful=True)
        self._slots = []
        for lease in self._leases.values():
            if lease is not None:
                lease.release()
        self._leases.clear()

    def imap(self, tasks: Iterable[EpisodeTask]) -> Iterator[EpisodeOutcome]:
        """Run ``tasks``; yields one outcome per task in finishing order."""
        pending = deque(tasks)
        attempts: dict[EpisodeTask, int] = {}
        if not pending:
            return
        if self.ctx.get_start_method() == "forkserver":  # takes effect if no fork server runs yet
            self.ctx.set_forkserver_preload(list(preload_for(pending[0].agent, self.limits)))
        while len(self._slots) < min(self.workers, len(pending)):
            self._slots.append(_Slot(self.ctx, self.limits, self._leases))
        while pending or any(s.task is not None for s in self._slots):
            yield from self._start_free(pending, attempts)
            busy = {s.conn: s for s in self._slots if s.task is not None}
            for conn in wait(list(busy), timeout=POLL_S):
                yield from self._heard(conn, busy[conn], attempts, pending)
            yield from self._watchdog(attempts, pending)

    def _start_free(self, pending: deque, attempts: dict) -> Iterator[EpisodeOutcome]:
        """Start the next tasks in the free slots (a task whose agent's env options are refused ends at once)."""
        for slot in self._slots:
            while slot.task is None and pending:
                task = pending.popleft()
                attempts[task] = attempts.get(task, 0) + 1
                env = self.agent_env(task.agent)
                if isinstance(env, str):
                    yield EpisodeOutcome(blank_records(task, AGENT_ERROR, env), attempts[task], 0.0, 0.0)
                    continue
                slot.run(task, env)

    def _heard(self, conn, slot: _Slot, attempts: dict, pending: deque) -> Iterator[EpisodeOutcome]:
        """What a slot's env process sent (its outcome once it is done), or its death."""
        try:
            kind, payload = conn.recv()
        except (EOFError, OSError):
            task, agents_turn = slot.task, slot.agents_turn()
            reason = f"env process died ({slot.exit_codes()})"
            slot.stop(graceful=False)
            if agents_turn:
                yield self._agents_fault(task, reason, attempts)
            else:
                yield from self._sim_failure(task, reason, attempts, pending)
            return
        slot.last_seen = time.monotonic()
        slot.heard_from = True
        if kind != "done":
            return
        task = slot.task
        slot.task = None
        failed = payload["status"] == AGENT_ERROR
        code = slot.end_agent(wait_s=1.0 if failed else 0.0)
        if payload["restart"]:
            slot.stop(graceful=False)
        if payload["status"] == SIM_ERROR:
            yield from self._sim_failure(task, payload["records"][0]["error"], attempts, pending)
            return
        records = tuple(EpisodeRecord(**row) for row in payload["records"])
        if failed and code:
            records = tuple(dataclasses.replace(r, error=f"{r.error}\n({exit_note(code, self.limits)})") for r in records)
        yield EpisodeOutcome(self._with_attempts(records, task), attempts[task], payload["max_decision_s"],
                             payload["mean_decision_s"])

    def _watchdog(self, attempts: dict, pending: deque) -> Iterator[EpisodeOutcome]:
        """Kill the env processes silent past their allowance; the episode is the agent's failure if it had the turn."""
        now = time.monotonic()
        for slot in self._slots:
            allowance = slot.silent_for(now) if slot.task is not None else None
            if allowance is not None:
                task, agents_turn = slot.task, slot.agents_turn()
                what = "no progress from the simulation" if slot.heard_from else "the env process did not start"
                slot.stop(graceful=False)
                reason = f"watchdog: {what} for {allowance:g} s; env process killed"
                if agents_turn:
                    yield self._agents_fault(task, reason, attempts)
                else:
                    yield from self._sim_failure(task, reason, attempts, pending)

    def _agents_fault(self, task: EpisodeTask, reason: str, attempts: dict) -> EpisodeOutcome:
        """The env process died or stalled while the agent had the turn: the simulator was idle,
        waiting for the agent's answer, so the agent (which may have killed or stopped it) fails
        the episode; it is not retried."""
        error = (f"{reason} while the agent had the turn (waiting for its answer, the simulator was idle): "
                 "the episode is the agent's failure, not retried")
        return EpisodeOutcome(self._with_attempts(blank_records(task, AGENT_ERROR, error), task), attempts[task],
                              0.0, 0.0)

    def _with_attempts(self, records: tuple[EpisodeRecord, ...], task: EpisodeTask) -> tuple[EpisodeRecord, ...]:
        """``records`` (an episode's, one per vehicle) with the earlier attempts of their episode (simulator
        failures that were retried) added to each one's ``error``, so a retry is never silent."""
        earlier = self._failed_attempts.pop(task, [])
        if not earlier:
            return records
        lines = [f"attempt {k} of {len(earlier) + 1}: {why}" for k, why in enumerate(earlier, start=1)]
        note = f"{RETRIED}: recorded from attempt {len(earlier) + 1}; " + "; ".join(lines)
        return tuple(dataclasses.replace(r, error=f"{r.error}\n{note}" if r.error else note) for r in records)

    def _sim_failure(self, task: EpisodeTask, reason: str, attempts: dict, pending: deque) -> Iterator[EpisodeOutcome]:
        """Retry ``task`` (at the front of the queue; the record it ends with names this attempt)
        or, out of retries, yield its sim_error record (naming every attempt)."""
        if attempts[task] <= self.limits.retries:
            self._failed_attempts.setdefault(task, []).append(" ".join(reason.split())[:500])
            pending.appendleft(task)
            return
        yield EpisodeOutcome(self._with_attempts(blank_records(task, SIM_ERROR, reason), task), attempts[task], 0.0, 0.0)
