"""The live server under fuzzed requests: every message gets a reply, the server never dies."""

from __future__ import annotations

import json

import zmq
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_server_protocol import TinySim

from vtr.runtime import protocol
from vtr.sim2d.server import ServerConfig, ServerThread

fuzz_frames = st.one_of(
    st.lists(st.binary(max_size=48), min_size=1, max_size=3),
    st.builds(
        lambda cmd, key, value: [
            json.dumps({"proto": "vtr-sim", "version": 1, "cmd": cmd, "seq": 1, key: value}).encode()
        ],
        st.sampled_from(protocol.COMMANDS),
        st.sampled_from(["seq", "v", "w", "duration", "pose", "seed", "session", "stamp"]),
        st.recursive(
            st.none()
            | st.integers(-(10**40), 10**40)
            | st.floats().filter(lambda x: x == x)
            | st.text(max_size=4),
            lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=3), c, max_size=3),
            max_leaves=10,
        ),
    ),
)


def test_the_live_server_answers_every_fuzzed_request_and_keeps_serving():
    sim = TinySim()
    cfg = ServerConfig(bind="tcp://127.0.0.1:*", poll_ms=10)
    with ServerThread(sim, cfg) as server:
        ctx = zmq.Context()
        sock = ctx.socket(zmq.REQ)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.RCVTIMEO, 5000)
        sock.connect(server.endpoint)

        @settings(max_examples=120, deadline=None, suppress_health_check=list(HealthCheck))
        @given(fuzz_frames)
        def one(frames):
            sock.send_multipart(frames)
            reply = protocol.decode_reply(sock.recv_multipart())  # a reply, and a well-formed one
            assert reply.session == server.server.session and (reply.ok or reply.error)

        try:
            one()
            sock.send_multipart(protocol.encode_request("observe", 7))
            assert protocol.decode_reply(sock.recv_multipart(), expect_seq=7).ok
        finally:
            sock.close()
            ctx.term()
    assert server.server.requests >= 121
