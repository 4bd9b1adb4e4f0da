"""The channel between the env process and the agent process, and the data-only codec of the agent's replies.

The two processes share a connected Unix stream socket. Every message is one *frame*: a 4-byte
big-endian length, then that many bytes.

env → agent (requests): pickled tuples ``("reset", n, info)`` and ``("act", n, observation, info)``,
    ``n`` counting the channel's requests from 1. Pickle is safe in this direction only: the env
    process is trusted, and the agent process unpickling what the env sends can harm nothing but
    the agent.

agent → env (replies): never pickle. A reply is a tag byte, the number ``n`` of the request it
    answers (little-endian uint32; 0 for ready), and a body. The env process decodes it with
    ``struct`` and ``numpy.frombuffer`` and a length-capped UTF-8 decode, none of which can run code:

    ========  ==========================================  =====================================
    tag       body                                        meaning
    ========  ==========================================  =====================================
    ``R``     UTF-8 JSON, ≤ ``MAX_TEXT_BYTES``            ready: the agent is built; the JSON
                                                          describes it (``AgentDescription``)
    ``E``     UTF-8 text, ≤ ``MAX_TEXT_BYTES``            the agent raised; the text says what
    ``K``     empty                                       ``reset`` done
    ``A``     little-endian int64                         a discrete action
    ``V``     1 … ``MAX_VECTOR`` little-endian float64    a continuous action (control agents)
    ``M``     UTF-8 JSON object, ≤ ``MAX_SCENE_BYTES``:   the actions of a scene's deciding
              vehicle id → integer or list of floats      vehicles (``scene_env``), one each
    ========  ==========================================  =====================================

    A scene's ``act`` request carries ``{vehicle: observation}`` and ``{"vehicles": {vehicle: info}}``;
    its reply must be an ``M`` whose vehicles are exactly the observed ones (the env process checks
    that: an agent cannot act for a vehicle that does not decide, nor leave one out). Vehicle ids
    match ``VEHICLE_ID`` (at most ``MAX_VEHICLES``), integers fit in int64, float lists hold 1 …
    ``MAX_VECTOR`` finite numbers.

    Anything else (an unknown tag, a wrong body length, a frame over ``MAX_REPLY_BYTES``, a
    reply to another request than the pending one, data sent while no request is pending,
    invalid UTF-8 or JSON, a JSON document off the schema) is a ``ProtocolError``: the agent's
    error. So each request gets exactly one reply, and a flood or replay of replies fails.

The env side reads and writes with deadlines (``EnvEnd``): an agent that stops reading its
requests, sends half a frame and stalls, or never answers cannot block the env process, which
keeps sending heartbeats while it waits.
"""

from __future__ import annotations

import json
import math
import pickle
import re
import socket
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

MAX_TEXT_BYTES = 16 * 1024
"""Longest text body (ready description, error message) of a reply [bytes]."""
MAX_VECTOR = 64
"""Most floats in a continuous action."""
MAX_VEHICLES = 64
"""Most vehicles in one scene reply."""
MAX_SCENE_BYTES = 64 * 1024
"""Longest JSON body of a scene reply [bytes]."""
VEHICLE_ID = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,31}")
"""What a vehicle id of a scene reply may be (``ego``, ``ego1`` ...)."""
MAX_REPLY_BYTES = 5 + max(MAX_TEXT_BYTES, 8 * MAX_VECTOR, MAX_SCENE_BYTES)
"""Longest reply frame the env process accepts [bytes]; a longer one is the agent's error."""
MAX_DESCRIPTION_ITEMS = 16
"""Most ``env_kwargs`` entries in a ready description."""
MAX_NAME_CHARS = 200
"""Longest ``env_factory``, option name or fingerprint in a ready description [characters]."""

_HEADER = struct.Struct("!I")
_INT = struct.Struct("<q")
_REQUEST = struct.Struct("<I")

READY, ERROR, OK, ACTION, ACTIONS = "ready", "error", "ok", "action", "actions"
"""Kinds of a decoded reply."""


class ProtocolError(Exception):
    """The agent broke the channel's protocol (the message says how): the agent's fault."""


class ChannelClosed(Exception):
    """The other end closed the channel (its process exited or closed the socket)."""


class ChannelTimeout(Exception):
    """The other end did not read or write within the deadline."""


@dataclass(frozen=True)
class AgentDescription:
    """What a built agent says about itself in its ready reply.

    Attributes:
        env_factory: ``module:callable`` of the env the agent needs (the flat baseline's control
            env); None for the behavior env. The evaluator accepts only known factories.
        env_kwargs: env options as sorted ``(name, value)`` pairs, values JSON scalars.
        fingerprint: the agent's checkpoint hash ("" when it has none).
    """

    env_factory: str | None = None
    env_kwargs: tuple[tuple[str, str | int | float | bool | None], ...] = ()
    fingerprint: str = ""

    def to_json(self) -> str:
        return json.dumps({"env_factory": self.env_factory, "env_kwargs": dict(self.env_kwargs),
                           "fingerprint": self.fingerprint}, sort_keys=True)

    @classmethod
    def of(cls, agent: Any) -> "AgentDescription":
        """The description of a built agent (from its ``env_factory``, ``env_kwargs`` and
        ``fingerprint`` attributes); raises ValueError when they do not fit the schema."""
        from hbmp_bench.agents.base import agent_env_kwargs

        factory = getattr(agent, "env_factory", None)
        kwargs = agent_env_kwargs(agent)
        return parse_description(json.dumps({"env_factory": factory, "env_kwargs": kwargs,
                                             "fingerprint": str(getattr(agent, "fingerprint", "") or "")}))


def parse_description(text: str) -> AgentDescription:
    """An ``AgentDescription`` from its JSON text; raises ValueError for anything off the schema
    (unknown keys, wrong types, non-finite numbers, too many or too long entries)."""
    try:
        doc = json.loads(text, parse_constant=_reject_constant)
    except (json.JSONDecodeError, RecursionError) as exc:
        raise ValueError(f"not JSON: {exc}") from None
    if not isinstance(doc, dict) or set(doc) != {"env_factory", "env_kwargs", "fingerprint"}:
        raise ValueError("want a JSON object with exactly env_factory, env_kwargs and fingerprint")
    factory, kwargs, fingerprint = doc["env_factory"], doc["env_kwargs"], doc["fingerprint"]
    if factory is not None and not (isinstance(factory, str) and 0 < len(factory) <= MAX_NAME_CHARS):
        raise ValueError(f"env_factory must be null or a string of at most {MAX_NAME_CHARS} characters")
    if not isinstance(fingerprint, str) or len(fingerprint) > MAX_NAME_CHARS:
        raise ValueError(f"fingerprint must be a string of at most {MAX_NAME_CHARS} characters")
    if not isinstance(kwargs, dict) or len(kwargs) > MAX_DESCRIPTION_ITEMS:
        raise ValueError(f"env_kwargs must be an object of at most {MAX_DESCRIPTION_ITEMS} entries")
    for name, value in kwargs.items():
        if len(name) > MAX_NAME_CHARS:
            raise ValueError(f"env_kwargs names must have at most {MAX_NAME_CHARS} characters")
        if not (value is None or isinstance(value, (str, int, float, bool))):
            raise ValueError(f"env_kwargs[{name!r}] must be a JSON scalar, got {type(value).__name__}")
        if isinstance(value, str) and len(value) > MAX_NAME_CHARS:
            raise ValueError(f"env_kwargs[{name!r}] must have at most {MAX_NAME_CHARS} characters")
    return AgentDescription(factory, tuple(sorted(kwargs.items())), fingerprint)


def _reject_constant(name: str):
    raise ValueError(f"{name} is not allowed")


def _no_repeats(pairs: list[tuple[str, object]]) -> dict:
    """A JSON object's pairs as a dict; ValueError when a name repeats (a vehicle acted for twice)."""
    doc = dict(pairs)
    if len(doc) != len(pairs):
        raise ValueError("a name repeats")
    return doc


# ---------------------------------------------------------------------------------------------- codec


def text_body(text: str) -> bytes:
    """``text`` as UTF-8, cut to ``MAX_TEXT_BYTES`` on a character boundary."""
    data = text.encode("utf-8", errors="replace")
    if len(data) > MAX_TEXT_BYTES:
        data = data[:MAX_TEXT_BYTES].decode("utf-8", errors="ignore").encode("utf-8")
    return data


def _reply(tag: bytes, request: int, body: bytes = b"") -> bytes:
    return tag + _REQUEST.pack(request) + body


def encode_ready(description: AgentDescription) -> bytes:
    return _reply(b"R", 0, text_body(description.to_json()))


def encode_error(text: str, request: int = 0) -> bytes:
    return _reply(b"E", request, text_body(text))


def encode_ok(request: int) -> bytes:
    return _reply(b"K", request)


def encode_action(action: int | tuple[float, ...], request: int) -> bytes:
    """An action from ``agent_process.as_action`` as the reply to request ``request``; raises
    ValueError when it cannot be sent (an integer outside int64, more than ``MAX_VECTOR`` floats)."""
    if isinstance(action, int):
        try:
            return _reply(b"A", request, _INT.pack(action))
        except struct.error:
            raise ValueError(f"integer action {action} does not fit in 64 bits") from None
    if not 0 < len(action) <= MAX_VECTOR:
        raise ValueError(f"a vector action has 1 to {MAX_VECTOR} entries, got {len(action)}")
    return _reply(b"V", request, np.asarray(action, dtype="<f8").tobytes())


def encode_actions(actions: dict[str, int | tuple[float, ...]], request: int) -> bytes:
    """A scene's actions (vehicle id → an action from ``agent_process.as_action``) as the reply to
    request ``request``; raises ValueError when they cannot be sent (see the module docstring)."""
    if not isinstance(actions, dict) or not 0 < len(actions) <= MAX_VEHICLES:
        raise ValueError(f"a scene's actions are a dict of 1 to {MAX_VEHICLES} vehicles, got "
                         f"{type(actions).__name__} of {len(actions) if isinstance(actions, dict) else '?'}")
    doc = {}
    for vehicle, action in actions.items():
        if not isinstance(vehicle, str) or not VEHICLE_ID.fullmatch(vehicle):
            raise ValueError(f"vehicle id {vehicle!r} is not a vehicle id (letters, digits, _; at most 32)")
        _check_scene_action(vehicle, action)
        doc[vehicle] = action if isinstance(action, int) else list(action)
    body = json.dumps(doc, allow_nan=False, separators=(",", ":")).encode("utf-8")
    if len(body) > MAX_SCENE_BYTES:
        raise ValueError(f"a scene's actions take {len(body)} bytes, the limit is {MAX_SCENE_BYTES}")
    return _reply(b"M", request, body)


def _check_scene_action(vehicle: str, action: object) -> None:
    if isinstance(action, bool):
        raise ValueError(f"the action of {vehicle} is a bool")
    if isinstance(action, int):
        if not -2**63 <= action < 2**63:
            raise ValueError(f"the action of {vehicle}, {action}, does not fit in 64 bits")
        return
    if not isinstance(action, (tuple, list)) or not 0 < len(action) <= MAX_VECTOR or not all(
            isinstance(x, float) and not isinstance(x, bool) and math.isfinite(x) for x in action):
        raise ValueError(f"the action of {vehicle} is no integer nor 1 to {MAX_VECTOR} finite floats: {action!r:.80}")


@dataclass(frozen=True)
class Reply:
    """A decoded reply: ``kind`` one of ``READY``, ``ERROR``, ``OK``, ``ACTION``, ``ACTIONS``; ``value`` an
    ``AgentDescription``, the error text, None, the action (int, or tuple of floats) or a scene's
    actions (dict vehicle id → int or tuple of floats);
    ``request`` the number of the request it answers (0: none)."""

    kind: str
    value: Any = None
    request: int = 0


def decode_reply(frame: bytes) -> Reply:
    """Decode one reply frame; raises ``ProtocolError`` for anything that is not one of the
    formats in the module docstring. Runs no code from the frame."""
    if len(frame) < 1 + _REQUEST.size:
        raise ProtocolError(f"reply of {len(frame)} bytes, too short for a tag and a request number")
    if len(frame) > MAX_REPLY_BYTES:
        raise ProtocolError(f"reply of {len(frame)} bytes, the limit is {MAX_REPLY_BYTES}")
    tag, (request,), body = frame[:1], _REQUEST.unpack(frame[1:5]), frame[5:]
    if tag not in (b"R", b"E", b"K", b"A", b"V", b"M"):
        raise ProtocolError(f"unknown reply tag {tag!r} ({len(frame)} bytes)")
    reply = _decode_body(tag, body)
    return Reply(reply.kind, reply.value, request)


def _decode_body(tag: bytes, body: bytes) -> Reply:
    if tag in (b"R", b"E"):
        try:
            text = body.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ProtocolError(f"reply text is not UTF-8 ({exc.reason} at byte {exc.start})") from None
        if tag == b"E":
            return Reply(ERROR, text)
        try:
            return Reply(READY, parse_description(text))
        except ValueError as exc:
            raise ProtocolError(f"ready description off its schema: {exc}") from None
    if tag == b"K":
        if body:
            raise ProtocolError(f"reset acknowledgement with {len(body)} stray bytes")
        return Reply(OK)
    if tag == b"A":
        if len(body) != _INT.size:
            raise ProtocolError(f"integer action of {len(body)} bytes, want {_INT.size}")
        return Reply(ACTION, _INT.unpack(body)[0])
    if tag == b"V":
        if not body or len(body) % 8 or len(body) // 8 > MAX_VECTOR:
            raise ProtocolError(f"vector action of {len(body)} bytes, want 8 to {8 * MAX_VECTOR} in steps of 8")
        values = tuple(float(x) for x in np.frombuffer(body, dtype="<f8"))
        if not all(math.isfinite(x) for x in values):
            raise ProtocolError("vector action with a NaN or infinite entry")
        return Reply(ACTION, values)
    if tag == b"M":
        return Reply(ACTIONS, _decode_scene(body))
    raise AssertionError(tag)


def _decode_scene(body: bytes) -> dict[str, int | tuple[float, ...]]:
    """The actions of a scene reply's JSON body, checked against the module docstring's rules."""
    if len(body) > MAX_SCENE_BYTES:
        raise ProtocolError(f"scene actions of {len(body)} bytes, the limit is {MAX_SCENE_BYTES}")
    try:
        doc = json.loads(body.decode("utf-8"), parse_constant=_reject_constant, object_pairs_hook=_no_repeats)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise ProtocolError(f"scene actions are not UTF-8 JSON of unique vehicles: {exc}") from None
    if not isinstance(doc, dict) or not 0 < len(doc) <= MAX_VEHICLES:
        raise ProtocolError(f"scene actions must be a JSON object of 1 to {MAX_VEHICLES} vehicles")
    actions: dict[str, int | tuple[float, ...]] = {}
    for vehicle, action in doc.items():
        if not VEHICLE_ID.fullmatch(vehicle):
            raise ProtocolError(f"scene actions name {vehicle[:40]!r}, not a vehicle id")
        if isinstance(action, list):
            action = tuple(float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) else x for x in action)
        try:
            _check_scene_action(vehicle, action)
        except ValueError as exc:
            raise ProtocolError(str(exc)) from None
        actions[vehicle] = action
    return actions


# ---------------------------------------------------------------------------------------------- frames


def socket_from(obj: Any) -> socket.socket:
    """A socket object for a socket or a file descriptor of one (the descriptor is owned by the result)."""
    return obj if isinstance(obj, socket.socket) else socket.socket(fileno=int(obj))


class AgentEnd:
    """The agent process's end: blocking reads of pickled requests, writes of encoded replies."""

    def __init__(self, sock: socket.socket):
        self.sock = sock
        self.sock.settimeout(None)

    def receive(self) -> tuple:
        """The next request; raises ``ChannelClosed`` when the env process closed the channel."""
        (length,) = _HEADER.unpack(self._exactly(_HEADER.size))
        return pickle.loads(self._exactly(length))

    def reply(self, payload: bytes) -> None:
        self.sock.sendall(_HEADER.pack(len(payload)) + payload)

    def _exactly(self, n: int) -> bytes:
        buf = bytearray(n)
        view, got = memoryview(buf), 0
        while got < n:
            k = self.sock.recv_into(view[got:])
            if k == 0:
                raise ChannelClosed("the env process closed the channel")
            got += k
        return bytes(buf)

    def close(self) -> None:
        self.sock.close()


class EnvEnd:
    """The env process's end: every read and write has a deadline, during which ``on_wait`` is
    called at least every ``wait_step_s`` (the env process's heartbeat).

    Args:
        sock: the connected socket.
        on_wait: called while waiting for the agent.
        wait_step_s: longest wait between two ``on_wait`` calls [s].
    """

    def __init__(self, sock: socket.socket, on_wait: Callable[[], None] = lambda: None, wait_step_s: float = 0.5):
        self.sock = sock
        self.on_wait = on_wait
        self.wait_step_s = wait_step_s
        self.requests = 0

    def request(self, message: tuple, timeout_s: float) -> None:
        """Send request ``(kind, *payload)`` pickled as ``(kind, n, *payload)``; raises
        ``ChannelTimeout`` when the agent does not take it in ``timeout_s`` [s], ``ChannelClosed``
        when its end is gone, ``ProtocolError`` when the agent sent something nobody asked for."""
        self._no_unsolicited_data()
        self.requests += 1
        data = pickle.dumps((message[0], self.requests, *message[1:]), protocol=pickle.HIGHEST_PROTOCOL)
        frame = memoryview(_HEADER.pack(len(data)) + data)
        deadline = time.monotonic() + timeout_s
        sent = 0
        while sent < len(frame):
            self.sock.settimeout(self._step(deadline))
            try:
                sent += self.sock.send(frame[sent:])
            except TimeoutError:
                self.on_wait()
            except OSError as exc:
                raise ChannelClosed(f"the agent's end is closed ({type(exc).__name__})") from None

    def reply(self, timeout_s: float) -> Reply:
        """The agent's reply to the pending request (the ready reply before any), decoded; raises
        ``ChannelTimeout``, ``ChannelClosed`` or ``ProtocolError`` (oversized, malformed, for
        another request, or followed by more data)."""
        deadline = time.monotonic() + timeout_s
        (length,) = _HEADER.unpack(self._exactly(_HEADER.size, deadline))
        if length > MAX_REPLY_BYTES:
            raise ProtocolError(f"reply of {length} bytes announced, the limit is {MAX_REPLY_BYTES}")
        reply = decode_reply(self._exactly(length, deadline))
        if reply.request != self.requests:
            raise ProtocolError(f"reply to request {reply.request}, but the pending request is {self.requests}")
        self._no_unsolicited_data()
        return reply

    def close(self) -> None:
        self.sock.close()

    def _step(self, deadline: float) -> float:
        left = deadline - time.monotonic()
        if left <= 0:
            raise ChannelTimeout("deadline passed")
        return min(self.wait_step_s, left)

    def _exactly(self, n: int, deadline: float) -> bytes:
        buf = bytearray(n)
        view, got = memoryview(buf), 0
        while got < n:
            self.sock.settimeout(self._step(deadline))
            try:
                k = self.sock.recv_into(view[got:])
            except TimeoutError:
                self.on_wait()
                continue
            except OSError as exc:
                raise ChannelClosed(f"the agent's end is closed ({type(exc).__name__})") from None
            if k == 0:
                raise ChannelClosed("the agent closed its channel" + (f" {got} bytes into a frame" if got else ""))
            got += k
        return bytes(buf)

    def _no_unsolicited_data(self) -> None:
        """Raise ``ProtocolError`` when the agent has sent bytes no request asked for."""
        self.sock.settimeout(0.0)
        try:
            pending = self.sock.recv(1, socket.MSG_PEEK)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return  # a broken end shows on the next read or write
        if pending:
            raise ProtocolError("the agent sent data nobody asked for (more than one reply to a request)")
