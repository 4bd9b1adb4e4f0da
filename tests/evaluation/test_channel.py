"""The agent channel: the data-only codec of replies, and the env end's deadlines (no simulation)."""

import math
import pickle
import re
import socket
import struct
import threading
import time

import pytest

from hbmp_bench.evaluation.channel import (
    ACTION,
    ERROR,
    MAX_REPLY_BYTES,
    MAX_TEXT_BYTES,
    MAX_VECTOR,
    OK,
    READY,
    AgentDescription,
    AgentEnd,
    ChannelClosed,
    ChannelTimeout,
    EnvEnd,
    ProtocolError,
    decode_reply,
    encode_action,
    encode_error,
    encode_ok,
    encode_ready,
    parse_description,
)


def framed(payload: bytes) -> bytes:
    return struct.pack("!I", len(payload)) + payload


@pytest.mark.parametrize("action", [0, 4, -3, 2**63 - 1, (0.5, -1.0), tuple(float(k) for k in range(MAX_VECTOR))])
def test_actions_round_trip(action):
    reply = decode_reply(encode_action(action))
    assert reply.kind == ACTION and reply.value == action


def test_ready_error_and_ok_round_trip():
    description = AgentDescription("hbmp_bench.envs.control_env:ControlEnv", (("observation", "vehicle_centric"),), "ab12")
    assert decode_reply(encode_ready(description)).value == description
    assert decode_reply(encode_ok()).kind == OK
    assert decode_reply(encode_error("boom ✓")).value == "boom ✓"
    long = decode_reply(encode_error("é" * MAX_TEXT_BYTES))  # cut on a character boundary
    assert long.kind == ERROR and len(long.value.encode()) <= MAX_TEXT_BYTES and set(long.value) == {"é"}


def test_unsendable_actions_are_refused_by_the_agent_side():
    with pytest.raises(ValueError, match="64 bits"):
        encode_action(2**70)
    with pytest.raises(ValueError, match="1 to"):
        encode_action(tuple([0.0] * (MAX_VECTOR + 1)))


class _Exploit:
    def __reduce__(self):
        return (exec, ("raise SystemExit('ran')",))


@pytest.mark.parametrize("frame, message", [
    (b"", "empty reply"),
    (pickle.dumps(("action", _Exploit())), "unknown reply tag b'\\x80'"),
    (b"Z", "unknown reply tag"),
    (b"A" + b"\x00" * 7, "integer action of 7 bytes"),
    (b"A" + b"\x00" * 9, "integer action of 9 bytes"),
    (b"V", "vector action of 0 bytes"),
    (b"V" + b"\x00" * 12, "vector action of 12 bytes"),
    (b"V" + struct.pack("<d", math.nan), "NaN or infinite"),
    (b"V" + struct.pack("<d", math.inf), "NaN or infinite"),
    (b"V" + b"\x00" * 8 * (MAX_VECTOR + 1), "vector action of"),
    (b"K!", "stray bytes"),
    (b"E\xff\xfe", "not UTF-8"),
    (b"R{not json", "off its schema: not JSON"),
    (b'R{"env_factory": null, "env_kwargs": {}}', "exactly env_factory, env_kwargs and fingerprint"),
    (b'R{"env_factory": null, "env_kwargs": {"x": [1]}, "fingerprint": ""}', "JSON scalar"),
    (b'R{"env_factory": null, "env_kwargs": {"x": NaN}, "fingerprint": ""}', "NaN is not allowed"),
    (b'R{"env_factory": 3, "env_kwargs": {}, "fingerprint": ""}', "env_factory must be null or a string"),
    (b"E" + b"x" * MAX_REPLY_BYTES, "the limit is"),
], ids=lambda v: v if isinstance(v, str) else None)
def test_malformed_replies_are_protocol_errors_and_run_nothing(frame, message):
    with pytest.raises(ProtocolError, match=re.escape(message)):
        decode_reply(frame)


def test_descriptions_follow_their_schema():
    assert parse_description('{"env_factory": null, "env_kwargs": {"observation": "deformed"}, "fingerprint": "x"}'
                             ) == AgentDescription(None, (("observation", "deformed"),), "x")
    with pytest.raises(ValueError, match="at most 16 entries"):
        parse_description('{"env_factory": null, "env_kwargs": {%s}, "fingerprint": ""}'
                          % ", ".join(f'"k{i}": 1' for i in range(17)))

    class Agent:
        env_kwargs = {"observation": object()}

    with pytest.raises(TypeError):
        AgentDescription.of(Agent())


@pytest.fixture
def pair():
    env_sock, agent_sock = socket.socketpair()
    waits = []
    yield EnvEnd(env_sock, on_wait=lambda: waits.append(time.monotonic()), wait_step_s=0.05), agent_sock, waits
    env_sock.close()
    agent_sock.close()


def test_a_request_and_its_reply(pair):
    end, agent_sock, _ = pair
    agent = AgentEnd(agent_sock)
    end.request(("act", {"x": 1}, {}), timeout_s=1.0)
    assert agent.receive() == ("act", {"x": 1}, {})
    agent.reply(encode_action(3))
    assert end.reply(timeout_s=1.0).value == 3


def test_an_agent_that_does_not_read_cannot_block_the_env(pair):
    end, _, waits = pair
    start = time.monotonic()
    with pytest.raises(ChannelTimeout):
        end.request(("act", b"\x00" * 50_000_000, {}), timeout_s=0.5)  # far more than the socket buffers
    assert 0.5 <= time.monotonic() - start < 3.0 and len(waits) >= 5  # heartbeats went on while it waited


def test_half_a_frame_times_out(pair):
    end, agent_sock, waits = pair
    agent_sock.sendall(struct.pack("!I", 100) + b"A" * 10)
    with pytest.raises(ChannelTimeout):
        end.reply(timeout_s=0.3)
    assert waits


def test_a_close_mid_frame_is_seen(pair):
    end, agent_sock, _ = pair
    agent_sock.sendall(struct.pack("!I", 100) + b"A" * 10)
    agent_sock.close()
    with pytest.raises(ChannelClosed, match="closed its channel 10 bytes into a frame"):
        end.reply(timeout_s=1.0)


def test_an_oversized_announcement_is_refused_before_reading_it(pair):
    end, agent_sock, _ = pair
    agent_sock.sendall(struct.pack("!I", 1 << 31))
    with pytest.raises(ProtocolError, match="announced"):
        end.reply(timeout_s=1.0)


def test_unsolicited_replies_are_refused(pair):
    end, agent_sock, _ = pair
    agent_sock.sendall(framed(encode_action(1)) * 2)
    with pytest.raises(ProtocolError, match="more than one reply"):
        end.reply(timeout_s=1.0)
    env_sock, agent_sock2 = socket.socketpair()
    try:
        agent_sock2.sendall(framed(encode_ok()))  # nobody asked yet
        with pytest.raises(ProtocolError, match="nobody asked for"):
            EnvEnd(env_sock).request(("reset", {}), timeout_s=1.0)
    finally:
        env_sock.close()
        agent_sock2.close()


def test_a_slow_but_honest_reply_arrives(pair):
    end, agent_sock, waits = pair

    def answer():
        time.sleep(0.2)
        agent_sock.sendall(framed(encode_ok())[:3])
        time.sleep(0.2)
        agent_sock.sendall(framed(encode_ok())[3:])

    thread = threading.Thread(target=answer)
    thread.start()
    assert end.reply(timeout_s=2.0).kind == OK
    thread.join()
    assert len(waits) >= 4


def test_ready_kind_is_decoded():
    assert decode_reply(encode_ready(AgentDescription())).kind == READY
