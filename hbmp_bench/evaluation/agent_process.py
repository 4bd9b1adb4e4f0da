"""The agent's own process: it builds the agent and answers ``reset`` / ``act`` requests on a pipe.

It holds no simulation: what it gets is the observation and info of each decision, pickled by
the env process. An agent that imports ``libsumo`` here finds no network loaded, so it cannot
move the ego or read other vehicles.

Protocol (tuples on one duplex pipe to the env process):
    agent → env  ``("ready", None)`` once built, or ``("error", text)`` and exit;
    env → agent  ``("reset", info)`` → ``("ok", None)``;
    env → agent  ``("act", observation, info)`` → ``("action", int)``;
    any exception in the agent → ``("error", text)`` (the process keeps serving).
The process exits when the pipe closes.
"""

from __future__ import annotations

import operator
import traceback
from multiprocessing.connection import Connection

import numpy as np

TRACEBACK_LIMIT = 6
"""Innermost frames of an agent traceback kept in the error text."""


def _error_text(stage: str) -> str:
    return f"agent {stage} raised:\n" + traceback.format_exc(limit=-TRACEBACK_LIMIT).rstrip()


def as_action(value: object) -> int | tuple[float, ...]:
    """An agent's action as a plain int (behavior agents) or a tuple of floats (control agents,
    e.g. the flat baseline's ``[accel, steer]``); raises TypeError for anything else (bools,
    strings, nested or empty arrays). The env process checks it against its action space."""
    if isinstance(value, bool):
        raise TypeError(f"action must be an integer, got bool {value!r}")
    try:
        return int(operator.index(value))
    except TypeError:
        pass
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        array = None
    if array is not None and array.ndim == 1 and array.size > 0 and not isinstance(value, (str, bytes)):
        return tuple(float(x) for x in array)
    raise TypeError(f"action must be an integer or a 1-D vector of numbers, got {type(value).__name__} {value!r:.80}")


def agent_main(conn: Connection, spec: str, lifeline: Connection, environ: dict[str, str] | None = None) -> None:
    """Entry point of the agent process (started by the episode pool with the caller's ``environ``;
    it exits when ``lifeline`` closes)."""
    from hbmp_bench.agents import load_agent
    from hbmp_bench.evaluation.tasks import adopt_environment, watch_lifeline

    watch_lifeline(lifeline)
    adopt_environment(environ)
    try:
        agent = load_agent(spec)
    except BaseException:  # noqa: BLE001 - every failure is reported to the env process
        conn.send(("error", _error_text(f"{spec!r} could not be built: load_agent")))
        conn.close()
        return
    conn.send(("ready", None))
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):
            return
        kind = message[0]
        try:
            if kind == "reset":
                agent.reset(message[1])
                reply = ("ok", None)
            elif kind == "act":
                raw = agent.act(message[1], message[2])
                try:
                    reply = ("action", as_action(raw))
                except TypeError as exc:
                    reply = ("error", f"invalid action: {exc}")
            elif kind == "stop":
                return
            else:
                reply = ("error", f"unknown request {kind!r}")
        except Exception:  # noqa: BLE001
            reply = ("error", _error_text(f"{kind}()"))
        try:
            conn.send(reply)
        except (BrokenPipeError, OSError):
            return
