"""SimClient over real ZeroMQ on 127.0.0.1: round trips, seq matching, stop-first timeouts, stamps, sessions."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable

import numpy as np
import pytest
import zmq
from runtime_fakes import FakeSim, render

from vtr.runtime import protocol
from vtr.runtime.client import SimClient
from vtr.runtime.protocol import BadFrameError, ProtocolError
from vtr.runtime.robot import Interrupted, LinkLost, Robot, RobotError, RobotRestarted
from vtr.sim2d.server import ServerConfig, ServerThread

Reply = list[bytes] | tuple[list[bytes], ...] | None


class ScriptedServer:
    """A ROUTER answering each request with ``respond(request)``: None stays silent, a list of frames is one
    reply, a tuple of them is several (a duplicating robot). ``arrivals`` records (monotonic time, request)."""

    def __init__(self, respond: Callable[[protocol.Request], Reply]) -> None:
        self.respond = respond
        self.arrivals: list[tuple[float, protocol.Request]] = []
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.ROUTER)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.bind("tcp://127.0.0.1:*")
        self.endpoint = self.sock.getsockopt_string(zmq.LAST_ENDPOINT)
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            if not self.sock.poll(5):
                continue
            ident, empty, *frames = self.sock.recv_multipart()
            req = protocol.decode_request(frames, None)
            self.arrivals.append((time.monotonic(), req))
            out = self.respond(req)
            for reply in [] if out is None else (list(out) if isinstance(out, tuple) else [out]):
                self.sock.send_multipart([ident, empty, *reply])

    def cmds(self) -> list[str]:
        return [r.cmd for _, r in self.arrivals]

    def close(self) -> None:
        self._stop.set()
        self.thread.join(2)
        self.sock.close()
        self.ctx.term()

    def __enter__(self) -> ScriptedServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def image_reply(
    req: protocol.Request, stamp: float, img: np.ndarray | None = None, **overrides
) -> list[bytes]:
    frames = protocol.encode_image_reply(req.cmd, req.seq, "s1", stamp, render(0.0) if img is None else img)
    if overrides:
        header = json.loads(frames[0])
        header.update(overrides)
        frames[0] = json.dumps(header).encode()
    return frames


def ok(req: protocol.Request, stamp: float = 0.0, session: str = "s1") -> list[bytes]:
    if req.cmd in protocol.IMAGE_COMMANDS:
        return image_reply(req, stamp, session=session)
    return protocol.encode_ok(req.cmd, req.seq, session, stamp)


def test_client_round_trips_against_the_server():
    sim = FakeSim()
    with (
        ServerThread(sim) as server,
        SimClient(server.endpoint, timeout_s=5.0, expect_shape=(16, 16)) as client,
    ):
        assert isinstance(client, Robot)
        hello = client.handshake()
        assert hello.protocol_version == 1 and hello.camera.width == 16 and hello.limits.v_max == 0.5
        assert hello.map == "corridor" and hello.mode == "lockstep"
        obs = client.reset(pose=(0.1, 0.0, 0.0), seed=3)
        assert obs.stamp == 0.0 and obs.pose == pytest.approx((0.1, 0.0, 0.0))
        np.testing.assert_array_equal(obs.image, render(0.1))
        obs = client.step(0.5, 0.0, 0.2)
        assert obs.stamp == pytest.approx(0.2) and obs.pose[0] == pytest.approx(0.2)
        client.stop()
        assert client.observe().stamp == pytest.approx(0.2)
        assert set(client.last_timing_ms) == {"receive", "decode"}
        with pytest.raises(ProtocolError, match="v_max"):
            client.step(0.7, 0.0, 0.1)  # the limits hello announced: refused before it is sent
        assert client.bad_frames == 0 and client.timeouts == 0
    assert sim.calls[0][0] == "reset" and sim.calls[0][2] == 3


def test_limits_announced_in_hello_replace_the_defaults():
    sim = FakeSim()
    cfg = ServerConfig(bind="tcp://127.0.0.1:*", v_max=0.8, w_max=0.3)
    with ServerThread(sim, cfg) as server, SimClient(server.endpoint, timeout_s=5.0) as client:
        client.handshake()
        client.step(0.7, 0.0, 0.1)  # over the paper's 0.5, under this robot's 0.8
        with pytest.raises(ProtocolError, match="w_max=0.3"):
            client.step(0.0, 0.5, 0.1)
    assert [c[1] for c in sim.calls if c[0] == "step"] == [0.7]


def test_refused_command_raises_robot_error_naming_the_reason():
    with (
        ScriptedServer(
            lambda req: protocol.encode_error("no map loaded", req.cmd, req.seq, "s1", 0.0)
        ) as server,
        SimClient(server.endpoint) as client,
        pytest.raises(RobotError, match="no map loaded"),
    ):
        client.observe()


def test_a_missed_observe_is_followed_by_a_stop_then_retried():
    def respond(req):
        return None if len(server.arrivals) == 1 else ok(req, 1.0)  # the first request is "lost"

    with ScriptedServer(respond) as server, SimClient(server.endpoint, timeout_s=0.2) as client:
        assert client.observe().stamp == 1.0
        assert client.timeouts == 1 and server.cmds() == ["observe", "stop", "observe"]
        assert [r.seq for _, r in server.arrivals] == [1, 2, 3]
    with SimClient("tcp://127.0.0.1:1", timeout_s=0.05, retries=2) as client:
        with pytest.raises(LinkLost, match="no reply from tcp://127.0.0.1:1 to 'observe' after 2 tries"):
            client.observe()


def test_a_silent_robot_gets_a_stop_within_half_a_second_and_never_the_step_again():
    silent_to_steps = lambda req: None if req.cmd == "step" else ok(req, 1.0)  # noqa: E731
    with ScriptedServer(silent_to_steps) as server, SimClient(server.endpoint) as client:
        with pytest.raises(BadFrameError, match="the robot was sent a stop"):
            client.step(0.3, 0.0, 0.1)
        assert server.cmds() == ["step", "stop"]
        (t_step, _), (t_stop, _) = server.arrivals
        assert t_stop - t_step < 0.5  # dt 0.1 + timeout 0.3 + delivery
        assert client.observe().stamp == 1.0  # the link is alive: the next exchange is clean
    with ScriptedServer(lambda req: None) as server, SimClient(server.endpoint) as client:
        with pytest.raises(LinkLost, match="nor to the stop"):
            client.step(0.3, 0.0, 0.1)
        assert server.cmds() == ["step", "stop", "stop", "stop"]  # stops are retried, the step never


BAD_FRAME_CASES = {
    "wrong shape": (lambda req: image_reply(req, 1.0, render(0.0, 8, 8)), "expected 16x16"),
    "wrong encoding": (lambda req: image_reply(req, 1.0, encoding="mono8"), "encoding"),
    "truncated payload": (
        lambda req: image_reply(req, 1.0)[:1] + [image_reply(req, 1.0)[1][:100]],
        "truncated",
    ),
    "unknown version": (lambda req: image_reply(req, 1.0, version=2), "version 2"),
    "float version": (lambda req: image_reply(req, 1.0, version=1.0), "version 1.0"),
    "seq from the future": (lambda req: image_reply(req, 1.0, seq=req.seq + 5), "last request sent was"),
    "float seq": (lambda req: image_reply(req, 1.0, seq=float(req.seq)), "must be an integer"),
    "huge integer": (
        lambda req: [image_reply(req, 1.0)[0].replace(b'"stamp":1.0', b'"stamp":' + b"9" * 400)],
        "out of range",
    ),
    "deep nesting": (
        lambda req: [image_reply(req, 1.0)[0][:-1] + b',"x":' + b"[" * 900 + b"]" * 900 + b"}"],
        "nested deeper",
    ),
    "not JSON": (lambda req: [b"\x00\x01"], "malformed JSON"),
}


@pytest.mark.parametrize("name", list(BAD_FRAME_CASES))
def test_bad_frames_are_rejected_and_counted_and_the_next_reply_is_in_sync(name):
    bad, fragment = BAD_FRAME_CASES[name]
    replies = iter([bad, lambda req: image_reply(req, 2.0)])
    with (
        ScriptedServer(lambda req: next(replies)(req)) as server,
        SimClient(server.endpoint, expect_shape=(16, 16)) as client,
    ):
        with pytest.raises(BadFrameError, match=fragment):
            client.observe()
        assert client.bad_frames == 1 and fragment in client.last_bad_frame
        assert client.observe().stamp == 2.0  # the next good frame is accepted


def test_a_duplicated_reply_is_skipped_and_costs_nothing():
    def respond(req):
        reply = ok(req, float(req.seq))
        return (reply, reply) if req.seq == 1 else reply

    with ScriptedServer(respond) as server, SimClient(server.endpoint) as client:
        stamps = [client.observe().stamp for _ in range(4)]
        assert stamps == [1.0, 2.0, 3.0, 4.0] and client.stale_replies == 1 and client.bad_frames == 0


def test_a_stamp_from_the_future_is_one_bad_frame_not_the_end_of_the_run():
    stamps = iter([1.0, 1.1, 1e9, 1.2, 1.3, 0.5, 1.4])
    with ScriptedServer(lambda req: ok(req, next(stamps))) as server, SimClient(server.endpoint) as client:
        assert [client.observe().stamp for _ in range(2)] == [1.0, 1.1]
        with pytest.raises(BadFrameError, match="from the future"):
            client.observe()
        assert [client.observe().stamp for _ in range(2)] == [1.2, 1.3]
        with pytest.raises(BadFrameError, match="stale frame"):
            client.observe()
        assert client.observe().stamp == 1.4 and client.bad_frames == 2


def test_a_new_session_confirmed_by_hello_is_a_restart_and_reset_restarts_the_clock():
    state = {"session": "s1", "stamp": 5.0}

    def respond(req):
        return ok(req, state["stamp"], state["session"])

    with ScriptedServer(respond) as server, SimClient(server.endpoint) as client:
        assert client.observe().stamp == 5.0
        state.update(session="s2", stamp=0.0)  # the robot rebooted: its clock starts again
        with pytest.raises(RobotRestarted, match="session s1 became s2"):
            client.observe()
        assert server.cmds()[-1] == "hello" and client.session_changes == 1 and client.session == "s2"
        state["stamp"] = 0.5
        assert client.step(0.1, 0.0, 0.5).stamp == 0.5
        state["stamp"] = 0.0
        assert client.reset().stamp == 0.0
        step, reset = server.arrivals[-2][1], server.arrivals[-1][1]
        assert step.session == "s2" and reset.session == "s2"  # motion commands name the session they are for


def test_one_reply_with_a_corrupt_session_is_one_bad_frame_not_a_restart():
    corrupt = {"left": 1}

    def respond(req):
        if req.cmd == "observe" and req.seq > 1 and corrupt["left"]:
            corrupt["left"] -= 1
            return ok(req, 1.0, "zz-corrupt")
        return ok(req, 1.0, "s1")

    with ScriptedServer(respond) as server, SimClient(server.endpoint) as client:
        client.observe()
        with pytest.raises(BadFrameError, match="still session s1"):
            client.observe()
        assert client.observe().stamp == 1.0 and client.session == "s1" and client.session_changes == 0


def test_a_rebooted_server_refuses_a_step_meant_for_its_previous_life():
    sim = FakeSim()
    with ServerThread(sim) as server, SimClient(server.endpoint, timeout_s=5.0) as client:
        client.handshake()
        client.session = "before-reboot"  # as if the server had restarted since the last reply
        with pytest.raises(RobotRestarted):
            client.step(0.3, 0.0, 0.1)
    assert [c for c in sim.calls if c[0] == "step"] == []  # refused, not executed


def test_an_oversized_reply_is_dropped_by_zeromq_before_it_takes_memory():
    big = lambda req: image_reply(req, 1.0, render(0.0, 64, 64))  # noqa: E731
    with (
        ScriptedServer(big) as server,
        SimClient(server.endpoint, timeout_s=0.1, max_message_bytes=4096) as client,
    ):
        with pytest.raises(LinkLost):
            client.observe()
        assert client.bad_frames == 0 and client.timeouts >= 3


def test_cancel_ends_a_wait_at_once_and_the_stop_still_goes_through():
    cancel = threading.Event()
    with (
        ScriptedServer(lambda req: None if req.cmd == "step" else ok(req)) as server,
        SimClient(server.endpoint, timeout_s=5.0, cancel=cancel) as client,
    ):
        threading.Timer(0.1, cancel.set).start()
        t0 = time.monotonic()
        with pytest.raises(Interrupted):
            client.step(0.3, 0.0, 0.1)
        assert time.monotonic() - t0 < 0.3
        client.stop()  # exempt from the cancel: the zero command always goes
        assert server.cmds() == ["step", "stop"]


def test_client_argument_validation():
    with pytest.raises(ValueError, match="timeout_s"):
        SimClient("tcp://127.0.0.1:1", timeout_s=0)
    with pytest.raises(ValueError, match="retries"):
        SimClient("tcp://127.0.0.1:1", retries=0)
    with pytest.raises(ValueError, match="no transport"):
        SimClient("127.0.0.1:5555")
    with pytest.raises(ValueError, match="no port"):
        SimClient("tcp://127.0.0.1")


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
