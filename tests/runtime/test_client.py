"""SimClient over real ZeroMQ on 127.0.0.1: round trips, Lazy Pirate retries, and rejected frames."""

from __future__ import annotations

import json
import threading
from collections.abc import Callable

import numpy as np
import pytest
import zmq
from runtime_fakes import FakeSim, render

from vtr.runtime import protocol
from vtr.runtime.client import SimClient
from vtr.runtime.protocol import BadFrameError
from vtr.runtime.robot import Robot, RobotError
from vtr.sim2d.server import ServerConfig, ServerThread


class ScriptedServer:
    """A REP socket answering each request with ``respond(request) -> frames`` (None: stay silent)."""

    def __init__(self, respond: Callable[[protocol.Request], list[bytes] | None]) -> None:
        self.respond = respond
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.ROUTER)  # ROUTER so that it may leave a request unanswered
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.bind("tcp://127.0.0.1:*")
        self.endpoint = self.sock.getsockopt_string(zmq.LAST_ENDPOINT)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            if not self.sock.poll(20):
                continue
            ident, empty, *frames = self.sock.recv_multipart()
            reply = self.respond(protocol.decode_request(frames))
            if reply is not None:
                self.sock.send_multipart([ident, empty, *reply])

    def close(self) -> None:
        self._stop.set()
        self.thread.join(2)
        self.sock.close()
        self.ctx.term()


def image_reply(
    req: protocol.Request, stamp: float, img: np.ndarray | None = None, **overrides
) -> list[bytes]:
    frames = protocol.encode_image_reply(req.cmd, req.seq, "s1", stamp, render(0.0) if img is None else img)
    if overrides:
        header = json.loads(frames[0])
        header.update(overrides)
        frames[0] = json.dumps(header).encode()
    return frames


def test_client_round_trips_against_the_server():
    sim = FakeSim()
    with (
        ServerThread(sim) as server,
        SimClient(server.endpoint, timeout_s=5.0, expect_shape=(16, 16)) as client,
    ):
        assert isinstance(client, Robot)
        hello = client.hello()
        assert hello["protocol_version"] == 1 and hello["camera"]["width"] == 16
        obs = client.reset(pose=(0.1, 0.0, 0.0), seed=3)
        assert obs.stamp == 0.0 and obs.pose == pytest.approx((0.1, 0.0, 0.0))
        np.testing.assert_array_equal(obs.image, render(0.1))
        obs = client.step(0.5, 0.0, 0.2)
        assert obs.stamp == pytest.approx(0.2) and obs.pose[0] == pytest.approx(0.2)
        client.stop()
        assert client.observe().stamp == pytest.approx(0.2)
        assert set(client.last_timing_ms) == {"receive", "decode"}
        with pytest.raises(protocol.ProtocolError, match="v_max"):
            client.step(0.7, 0.0, 0.1)  # refused before it is sent
        assert client.bad_frames == 0 and client.timeouts == 0
    assert sim.calls[0][0] == "reset" and sim.calls[0][2] == 3


def test_refused_command_raises_robot_error_naming_the_reason():
    server = ScriptedServer(lambda req: protocol.encode_error("no map loaded", req.cmd, req.seq))
    try:
        with (
            SimClient(server.endpoint, timeout_s=2.0) as client,
            pytest.raises(RobotError, match="no map loaded"),
        ):
            client.observe()
    finally:
        server.close()


def test_lazy_pirate_resends_after_a_lost_reply_and_gives_up_clearly():
    calls = []

    def respond(req):
        calls.append(req.seq)
        return None if len(calls) == 1 else image_reply(req, 1.0)  # the first request is "lost"

    server = ScriptedServer(respond)
    try:
        with SimClient(server.endpoint, timeout_s=0.3, retries=3) as client:
            assert client.observe().stamp == 1.0
            assert client.timeouts == 1 and calls == [1, 2]  # resent on a fresh socket with a new seq
    finally:
        server.close()
    with SimClient("tcp://127.0.0.1:1", timeout_s=0.1, retries=2) as client:
        with pytest.raises(RobotError, match="no reply from tcp://127.0.0.1:1 to 'observe' after 2 tries"):
            client.observe()
        assert client.timeouts == 2


BAD_FRAME_CASES = {
    "wrong shape": (lambda req: image_reply(req, 1.0, render(0.0, 8, 8)), "expected 16x16"),
    "wrong encoding": (lambda req: image_reply(req, 1.0, encoding="mono8"), "encoding"),
    "truncated payload": (
        lambda req: image_reply(req, 1.0)[:1] + [image_reply(req, 1.0)[1][:100]],
        "truncated",
    ),
    "unknown version": (lambda req: image_reply(req, 1.0, version=2), "version 2"),
    "out-of-order seq": (lambda req: image_reply(req, 1.0, seq=req.seq + 5), "stale or out of order"),
    "not JSON": (lambda req: [b"\x00\x01"], "malformed JSON"),
}


@pytest.mark.parametrize("name", list(BAD_FRAME_CASES))
def test_bad_frames_are_rejected_and_counted(name):
    bad, fragment = BAD_FRAME_CASES[name]
    replies = iter([bad, lambda req: image_reply(req, 2.0)])
    server = ScriptedServer(lambda req: next(replies)(req))
    try:
        with SimClient(server.endpoint, timeout_s=2.0, expect_shape=(16, 16)) as client:
            with pytest.raises(BadFrameError, match=fragment):
                client.observe()
            assert client.bad_frames == 1 and fragment in client.last_bad_frame
            assert client.observe().stamp == 2.0  # the next good frame is accepted
    finally:
        server.close()


def test_stale_stamps_are_rejected_but_a_restarted_server_or_reset_starts_a_new_clock():
    script = iter(
        [
            lambda req: image_reply(req, 5.0),
            lambda req: image_reply(req, 4.0),  # older than the last: stale
            lambda req: image_reply(req, 0.0, session="s2"),  # new session: the clock may restart
            lambda req: image_reply(req, 0.5, session="s2"),
            lambda req: image_reply(req, 0.0, session="s2"),  # reset: the clock restarts
        ]
    )
    server = ScriptedServer(lambda req: next(script)(req))
    try:
        with SimClient(server.endpoint, timeout_s=2.0) as client:
            assert client.observe().stamp == 5.0
            with pytest.raises(BadFrameError, match="stale frame"):
                client.observe()
            assert client.observe().stamp == 0.0 and client.session_changes == 1
            assert client.step(0.1, 0.0, 0.5).stamp == 0.5
            assert client.reset().stamp == 0.0
            assert client.bad_frames == 1
    finally:
        server.close()


def test_oversized_reply_is_rejected(tmp_path):
    server = ScriptedServer(lambda req: image_reply(req, 1.0, render(0.0, 64, 64)))
    try:
        with SimClient(server.endpoint, timeout_s=2.0, max_message_bytes=4096) as client:
            with pytest.raises(BadFrameError, match="exceeds the limit of 4096"):
                client.observe()
    finally:
        server.close()


def test_client_argument_validation():
    with pytest.raises(ValueError, match="timeout_s"):
        SimClient("tcp://127.0.0.1:1", timeout_s=0)
    with pytest.raises(ValueError, match="retries"):
        SimClient("tcp://127.0.0.1:1", retries=0)


def test_server_config_with_ephemeral_port_reports_the_real_endpoint():
    with ServerThread(FakeSim(), ServerConfig(bind="tcp://127.0.0.1:*")) as server:
        assert server.endpoint.startswith("tcp://127.0.0.1:") and not server.endpoint.endswith("*")


def test_an_interrupted_exchange_does_not_block_the_zero_command_that_follows(monkeypatch):
    sim = FakeSim()
    with ServerThread(sim) as server, SimClient(server.endpoint, timeout_s=5.0) as client:
        client.observe()
        sock_type = type(client._sock)
        real_poll = sock_type.poll

        def interrupted(self, *args, **kwargs):
            monkeypatch.setattr(sock_type, "poll", real_poll)
            raise KeyboardInterrupt

        monkeypatch.setattr(sock_type, "poll", interrupted)
        with pytest.raises(KeyboardInterrupt):
            client.step(0.2, 0.0, 0.1)
        client.stop()  # a fresh socket: the stop goes through
        assert server.server.last_cmd == "stop"
