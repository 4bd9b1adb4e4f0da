"""The agent's own process: it confines itself, builds the agent and answers ``reset`` / ``act`` requests.

It holds no simulation: what it gets is the observation and info of each decision, sent by the
env process. An agent that imports ``libsumo`` here finds no network loaded, so it cannot move
the ego or read other vehicles. The pool starts one agent process per episode.

Before any agent code runs (importing its module included) the process enters the sandbox
(``sandbox.enter_sandbox``: own session, no inherited descriptors, resource limits, and an
unprivileged user when the evaluator is root). Agents built by the package's own code alone
(registered agents, checkpoint files) are built just before the user switch, so a checkpoint
only the caller can read still loads; a ``module:Class`` agent is imported after it.

Protocol (frames on one socket to the env process, see ``channel``):
    agent → env  ready (with the agent's ``AgentDescription``) once built, or an error and exit;
    env → agent  ``("reset", n, info)`` → ok for request n;
    env → agent  ``("act", n, observation, info)`` → an action (int, or vector of floats) for request n;
                 in a scene (``scene=True``: several goal-directed vehicles, ``envs.scene_env``) the
                 observation is ``{vehicle: observation}`` and the reply ``{vehicle: action}``, from
                 the agent wrapped in ``agents.scene.SceneAgent``;
    any exception in the agent → an error text (the process keeps serving).
Requests are pickled by the (trusted) env process; replies are data only. The process exits
when the channel closes.
"""

from __future__ import annotations

import operator
import os
import socket
import sys
import traceback
from multiprocessing.connection import Connection
from typing import Any

import numpy as np

from hbmp_bench.errors import UserError
from hbmp_bench.evaluation import channel

TRACEBACK_LIMIT = 6
"""Innermost frames of an agent traceback kept in the error text."""

ONE_THREAD = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
"""Thread pools of the agent's numeric libraries (torch, numpy's BLAS), unless the caller's environment
sets them: an agent acts on one observation at a time, which more threads do not speed up, while
their spinning slows every process of a loaded machine. A learned agent's decision took over the 10 s
timeout on a 2-core machine running an evaluation beside a training run (2 of 500 il episodes)."""


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


def runs_only_package_code(spec: str) -> bool:
    """Whether building ``spec`` runs only this package's code: a registered agent (the fork
    server imported the package's agents only) or a checkpoint file (read as data, with
    ``torch.load(weights_only=True)``). A ``module:Class`` agent runs its own code."""
    from hbmp_bench.agents import AGENTS

    return spec in AGENTS or spec.endswith(".pt")


def _build(spec: str, hint: str = "", scene: bool = False) -> tuple[Any, str]:
    """(the agent, "") or (None, why it could not be built); ``scene``: the agent as the driver of a whole
    scene (``agents.scene.SceneAgent``: a batching agent drives every vehicle, any other one copy each)."""
    try:
        from hbmp_bench.agents import load_agent

        if scene:
            from hbmp_bench.agents.scene import SceneAgent

            agent = SceneAgent(spec)
        else:
            agent = load_agent(spec)
        channel.AgentDescription.of(agent)
        return agent, ""
    except (UserError, FileNotFoundError) as exc:  # already one line naming the agent and where it failed
        return None, f"agent could not be built: {exc}{hint}"
    except BaseException:  # noqa: BLE001 - every failure is reported to the env process
        return None, _error_text(f"{spec!r} could not be built: load_agent") + hint


def scene_actions(raw: object) -> dict[str, int | tuple[float, ...]]:
    """A scene agent's reply (``{vehicle: action}``) with each action made plain (:func:`as_action`);
    TypeError for anything but a dict."""
    if not isinstance(raw, dict):
        raise TypeError(f"a scene's actions must be a dict vehicle -> action, got {type(raw).__name__} {raw!r:.80}")
    return {vehicle: as_action(action) for vehicle, action in raw.items()}


def sandbox_entry(argv: list[str] | None = None) -> None:
    """Entry point of an agent process in the namespace sandbox (``namespaces.start_sandboxed``
    runs ``python -c`` this with one JSON argument): ``spec`` (the agent's name in records),
    ``load`` (what ``load_agent`` builds: the spec, a checkpoint's absolute path), ``sys_path``,
    the descriptors ``channel`` and ``lifeline``, ``limits`` (the ``RunnerLimits`` agent limits)
    and ``account`` (``[uid, gid]`` to switch to, or null to keep the user)."""
    import json
    import types

    config = json.loads((argv or sys.argv)[-1])
    sys.path[:] = list(config["sys_path"])
    sock = socket.socket(fileno=int(config["channel"]))
    lifeline = Connection(int(config["lifeline"]), writable=False)
    limits = types.SimpleNamespace(agent_user=None, **config["limits"])
    account = None
    if config.get("account") is not None:
        uid, gid = config["account"]
        account = types.SimpleNamespace(pw_uid=int(uid), pw_gid=int(gid), pw_name=f"agent-{uid}", pw_dir="/tmp")
    agent_main(sock, config["spec"], lifeline, limits, None, account=account, load=config.get("load"),
               scene=bool(config.get("scene")))


def agent_main(sock: socket.socket, spec: str, lifeline: Connection, limits, environ: dict[str, str] | None = None,
               account=None, load: str | None = None, scene: bool = False) -> None:
    """Entry point of the agent process (started by the episode pool with the caller's ``environ``;
    it exits when ``lifeline`` closes).

    An agent whose build runs only the package's code (``runs_only_package_code``) is built
    inside the sandbox but before the switch to ``agent_user`` (or ``account``, see
    ``sandbox.enter_sandbox``), so it may read a checkpoint only the caller can read; any other
    is built after the switch, so none of its code runs as root. ``load`` is what
    ``load_agent`` builds (default ``spec``). ``scene``: the episodes are scenes (every ``act``
    asks for every deciding vehicle's action; the agent is wrapped in ``agents.scene.SceneAgent``).
    """
    load = load or spec
    from hbmp_bench.evaluation.sandbox import SandboxError, enter_sandbox
    from hbmp_bench.evaluation.tasks import adopt_environment, watch_lifeline

    watch_lifeline(lifeline)
    adopt_environment(environ)
    threads = os.environ.get("OMP_NUM_THREADS", ONE_THREAD["OMP_NUM_THREADS"])
    for name in ONE_THREAD:  # a caller's OMP_NUM_THREADS sizes the others too (torch reads MKL's when it is set)
        os.environ.setdefault(name, threads)
    if "torch" in sys.modules:  # imported before the variables were set: its pool is sized already
        sys.modules["torch"].set_num_threads(int(os.environ["OMP_NUM_THREADS"]))
    end = channel.AgentEnd(sock)
    built: list[tuple[Any, str]] = []
    early = runs_only_package_code(load)
    try:
        user = enter_sandbox(limits, keep_fds=(sock.fileno(), lifeline.fileno()),
                             before_switch=(lambda: built.append(_build(load, scene=scene))) if early else None,
                             account=account)
    except SandboxError as exc:
        end.reply(channel.encode_error(f"the evaluator could not confine the agent process: {exc}"))
        return
    if not built:
        hint = "" if user is None else (
            f" (the agent process runs as user {user!r} because the evaluator runs as root: the agent's module and "
            "files must be readable by that user; only a trusted agent may run as root, with agent_user=None)")
        built.append(_build(load, hint, scene))
    agent, error = built[0]
    if agent is None:
        end.reply(channel.encode_error(error))
        end.close()
        return
    description = channel.AgentDescription.of(agent)
    end.reply(channel.encode_ready(description))
    while True:
        try:
            message = end.receive()
        except (channel.ChannelClosed, OSError):
            return
        kind, number, payload = message[0], message[1], message[2:]
        try:
            if kind == "reset":
                agent.reset(*payload)
                reply = channel.encode_ok(number)
            elif kind == "act":
                raw = agent.act(*payload)
                try:
                    reply = (channel.encode_actions(scene_actions(raw), number) if scene
                             else channel.encode_action(as_action(raw), number))
                except (TypeError, ValueError) as exc:
                    reply = channel.encode_error(f"invalid action: {exc}", number)
            else:
                reply = channel.encode_error(f"unknown request {kind!r}", number)
        except Exception:  # noqa: BLE001
            reply = channel.encode_error(_error_text(f"{kind}()"), number)
        try:
            end.reply(reply)
        except OSError:
            return
