"""A pool of isolated episode slots: per slot one env process and one agent process.

The pool (in the calling process) owns every child. Each slot pairs an env process, which holds
the SUMO simulation (libsumo: one per process), with an agent process connected to it by a pipe:
the agent sees the observations and infos the env process sends, nothing else. The pool hands
out one episode at a time per slot, watches heartbeats, and

- records an ``agent_error`` episode and restarts the slot when the agent raises, hangs past
  ``decision_timeout_s`` or dies;
- kills a slot whose env process sends no heartbeat for ``watchdog_s`` (``start_timeout_s``
  right after it starts) or dies, and retries that episode up to ``retries`` times before
  recording a ``sim_error``.

Outcomes are yielded as episodes finish, so a caller can append each record at once.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from collections import deque
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait

from hbmp_bench.evaluation.agent_process import agent_main
from hbmp_bench.evaluation.env_process import blank_record, env_main
from hbmp_bench.evaluation.tasks import EpisodeTask, RunnerLimits
from hbmp_bench.metrics.records import SIM_ERROR, EpisodeRecord

POLL_S = 0.2
"""How often the pool checks watchdogs while no message arrives [s]."""

PRELOAD = ("hbmp_bench.evaluation.env_process", "hbmp_bench.evaluation.agent_process", "hbmp_bench.envs.behavior_env",
           "hbmp_bench.agents")
"""Modules the fork server imports once, so a slot (re)starts in a fraction of a second."""


def default_start_method() -> str:
    """``forkserver`` where available (fast restarts, children share no state with the caller), else ``spawn``."""
    return "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"


@dataclass(frozen=True)
class EpisodeOutcome:
    """A finished episode: its record, how many attempts it took, and the agent's decision times [s]
    (round trip through the pipe; 0 when no decision was made)."""

    record: EpisodeRecord
    attempts: int
    max_decision_s: float
    mean_decision_s: float


class _Slot:
    """An env process and an agent process, started on first use and restarted after failures."""

    def __init__(self, ctx, agent: str, limits: RunnerLimits):
        self.ctx, self.agent, self.limits = ctx, agent, limits
        self.env_proc = self.agent_proc = None
        self.conn: Connection | None = None
        self.lifeline: Connection | None = None
        self.task: EpisodeTask | None = None
        self.last_seen = 0.0
        self.heard_from = False

    @property
    def alive(self) -> bool:
        return self.env_proc is not None

    def start(self) -> None:
        env_end, agent_end = self.ctx.Pipe(duplex=True)
        pool_end, env_pool_end = self.ctx.Pipe(duplex=True)
        life_r, self.lifeline = self.ctx.Pipe(duplex=False)
        environ = dict(os.environ)  # a fork server's children would otherwise see its start-time environment
        self.agent_proc = self.ctx.Process(target=agent_main, args=(agent_end, self.agent, life_r, environ),
                                           name="hbmp-agent")
        self.env_proc = self.ctx.Process(target=env_main, args=(env_pool_end, env_end, self.limits, life_r, environ),
                                         name="hbmp-env")
        self.agent_proc.start()
        self.env_proc.start()
        self.heard_from = False
        for end in (env_end, agent_end, env_pool_end, life_r):
            end.close()
        self.conn = pool_end

    def run(self, task: EpisodeTask) -> None:
        if not self.alive or task.agent != self.agent:
            self.stop()
            self.agent = task.agent
            self.start()
        self.task = task
        self.last_seen = time.monotonic()
        self.conn.send(("run", task))

    def stop(self, graceful: bool = True) -> None:
        """End both processes (a polite stop first when ``graceful``, then kill)."""
        if self.conn is not None:
            if graceful:
                try:
                    self.conn.send(("stop", None))
                except (OSError, BrokenPipeError):
                    pass
            self.conn.close()
        if self.lifeline is not None:
            self.lifeline.close()  # the children exit on this EOF
        for proc in (self.env_proc, self.agent_proc):
            if proc is None:
                continue
            proc.join(1.0 if graceful else 0.0)
            if proc.is_alive():
                proc.kill()
                proc.join(5.0)
        self.env_proc = self.agent_proc = self.conn = self.lifeline = None
        self.task = None

    def silent_for(self, now: float) -> float | None:
        """The allowance [s] this slot has gone past without a message, or None while within it."""
        allowance = self.limits.watchdog_s if self.heard_from else self.limits.start_timeout_s
        late = now - self.last_seen - allowance
        return allowance if late > 0 else None

    def exit_codes(self) -> str:
        """How the slot's processes ended (waits briefly for them to be reaped)."""
        for proc in (self.env_proc, self.agent_proc):
            if proc is not None:
                proc.join(0.5)
        return ", ".join(f"{p.name} exit code {p.exitcode}" for p in (self.env_proc, self.agent_proc) if p is not None)


class EpisodePool:
    """Isolated slots that run episodes; use as a context manager (``close`` ends every child).

    Args:
        workers: number of slots (each an env process plus an agent process).
        limits: timeouts, watchdog and retries.
        start_method: multiprocessing start method (default ``default_start_method()``); never
            ``fork``, which would copy the caller's threads and simulation state.
    """

    def __init__(self, workers: int = 1, limits: RunnerLimits | None = None, start_method: str | None = None):
        if workers <= 0:
            raise ValueError(f"workers must be > 0, got {workers}")
        start_method = start_method or default_start_method()
        if start_method not in ("forkserver", "spawn"):
            raise ValueError(f"start_method must be 'forkserver' or 'spawn', got {start_method!r}")
        self.workers = workers
        self.limits = limits or RunnerLimits()
        self.ctx = mp.get_context(start_method)
        if start_method == "forkserver":
            self.ctx.set_forkserver_preload(list(PRELOAD))
        self._slots: list[_Slot] = []

    def __enter__(self) -> "EpisodePool":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        for slot in self._slots:
            slot.stop(graceful=True)
        self._slots = []

    def imap(self, tasks: Iterable[EpisodeTask]) -> Iterator[EpisodeOutcome]:
        """Run ``tasks``; yields one outcome per task in finishing order."""
        pending = deque(tasks)
        attempts: dict[EpisodeTask, int] = {}
        if not pending:
            return
        while len(self._slots) < min(self.workers, len(pending)):
            self._slots.append(_Slot(self.ctx, pending[0].agent, self.limits))
        while pending or any(s.task is not None for s in self._slots):
            for slot in self._slots:
                if slot.task is None and pending:
                    task = pending.popleft()
                    attempts[task] = attempts.get(task, 0) + 1
                    slot.run(task)
            busy = {s.conn: s for s in self._slots if s.task is not None}
            for conn in wait(list(busy), timeout=POLL_S):
                slot = busy[conn]
                try:
                    kind, payload = conn.recv()
                except (EOFError, OSError):
                    task = slot.task
                    reason = f"env process died ({slot.exit_codes()})"
                    slot.stop(graceful=False)
                    yield from self._sim_failure(task, reason, attempts, pending)
                    continue
                slot.last_seen = time.monotonic()
                slot.heard_from = True
                if kind == "done":
                    task = slot.task
                    slot.task = None
                    if payload["restart"]:
                        slot.stop(graceful=False)
                    if payload["status"] == SIM_ERROR:
                        yield from self._sim_failure(task, payload["record"]["error"], attempts, pending)
                        continue
                    record = EpisodeRecord(**payload["record"])
                    yield EpisodeOutcome(record, attempts[task], payload["max_decision_s"], payload["mean_decision_s"])
            now = time.monotonic()
            for slot in self._slots:
                allowance = slot.silent_for(now) if slot.task is not None else None
                if allowance is not None:
                    task = slot.task
                    what = "no progress from the simulation" if slot.heard_from else "the env process did not start"
                    slot.stop(graceful=False)
                    reason = f"watchdog: {what} for {allowance:g} s; env process killed"
                    yield from self._sim_failure(task, reason, attempts, pending)

    def _sim_failure(self, task: EpisodeTask, reason: str, attempts: dict, pending: deque) -> Iterator[EpisodeOutcome]:
        """Retry ``task`` (at the front of the queue) or, out of retries, yield its sim_error record."""
        if attempts[task] <= self.limits.retries:
            pending.appendleft(task)
            return
        yield EpisodeOutcome(blank_record(task, SIM_ERROR, reason), attempts[task], 0.0, 0.0)
