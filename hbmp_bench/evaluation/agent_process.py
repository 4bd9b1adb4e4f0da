"""The agent's own process: it confines itself, builds the agent and answers ``reset`` / ``act`` requests.

It holds no simulation: what it gets is the observation and info of each decision, sent by the
env process. An agent that imports ``libsumo`` here finds no network loaded, so it cannot move
the ego or read other vehicles. The pool starts one agent process per episode.

Before any agent code runs (importing its module included) the process enters the sandbox
(``sandbox.enter_sandbox``: own session, no inherited descriptors, resource limits, and an
unprivileged user when the evaluator is root).

Protocol (frames on one socket to the env process, see ``channel``):
    agent → env  ready (with the agent's ``AgentDescription``) once built, or an error and exit;
    env → agent  ``("reset", info)`` → ok;
    env → agent  ``("act", observation, info)`` → an action (int, or vector of floats);
    any exception in the agent → an error text (the process keeps serving).
Requests are pickled by the (trusted) env process; replies are data only. The process exits
when the channel closes.
"""

from __future__ import annotations

import operator
import socket
import traceback
from multiprocessing.connection import Connection

import numpy as np

from hbmp_bench.errors import UserError
from hbmp_bench.evaluation import channel

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


def agent_main(sock: socket.socket, spec: str, lifeline: Connection, limits, environ: dict[str, str] | None = None) -> None:
    """Entry point of the agent process (started by the episode pool with the caller's ``environ``;
    it exits when ``lifeline`` closes)."""
    from hbmp_bench.evaluation.sandbox import SandboxError, enter_sandbox
    from hbmp_bench.evaluation.tasks import adopt_environment, watch_lifeline

    watch_lifeline(lifeline)
    adopt_environment(environ)
    end = channel.AgentEnd(sock)
    try:
        user = enter_sandbox(limits, keep_fds=(sock.fileno(), lifeline.fileno()))
    except SandboxError as exc:
        end.reply(channel.encode_error(f"the evaluator could not confine the agent process: {exc}"))
        return
    hint = "" if user is None else (
        f" (the agent process runs as user {user!r} because the evaluator runs as root: the agent's module and "
        "files must be readable by that user; only a trusted agent may run as root, with agent_user=None)")
    try:
        from hbmp_bench.agents import load_agent

        agent = load_agent(spec)
        description = channel.AgentDescription.of(agent)
    except UserError as exc:  # already one line naming the agent and where it failed
        end.reply(channel.encode_error(f"agent could not be built: {exc}{hint}"))
        end.close()
        return
    except BaseException:  # noqa: BLE001 - every failure is reported to the env process
        end.reply(channel.encode_error(_error_text(f"{spec!r} could not be built: load_agent") + hint))
        end.close()
        return
    end.reply(channel.encode_ready(description))
    while True:
        try:
            message = end.receive()
        except (channel.ChannelClosed, OSError):
            return
        kind = message[0]
        try:
            if kind == "reset":
                agent.reset(message[1])
                reply = channel.encode_ok()
            elif kind == "act":
                raw = agent.act(message[1], message[2])
                try:
                    reply = channel.encode_action(as_action(raw))
                except (TypeError, ValueError) as exc:
                    reply = channel.encode_error(f"invalid action: {exc}")
            else:
                reply = channel.encode_error(f"unknown request {kind!r}")
        except Exception:  # noqa: BLE001
            reply = channel.encode_error(_error_text(f"{kind}()"))
        try:
            end.reply(reply)
        except OSError:
            return
