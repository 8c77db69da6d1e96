"""The simulator server: every bad request gets an error naming the problem, and it keeps serving."""

from __future__ import annotations

import json
import math
from typing import Any, NamedTuple

import numpy as np
import pytest
import zmq

from vtr.runtime import protocol
from vtr.sim2d.server import ServerConfig, ServerThread, SimServer, start_server_process


class Pose(NamedTuple):
    x: float
    y: float
    yaw: float


class TinySim:
    """The sim2d.Simulator API: the image's red channel encodes x (in cm)."""

    def __init__(self) -> None:
        self.pose = Pose(0.0, 0.0, 0.0)
        self.time = 0.0
        self.collided = False
        self.steps: list[tuple[float, float, float]] = []
        self.fail_next = False

    def _img(self) -> np.ndarray:
        img = np.zeros((6, 8, 3), dtype=np.uint8)
        img[..., 0] = int(round(self.pose.x * 100)) % 256
        return img

    def reset(self, pose: Any = None, seed: int | None = None) -> np.ndarray:
        self.pose = Pose(0.0, 0.0, 0.0) if pose is None else Pose(pose.x, pose.y, pose.yaw)
        self.time = 0.0
        return self._img()

    def observe(self) -> np.ndarray:
        return self._img()

    def step(self, v: float, w: float, duration: float) -> np.ndarray:
        if self.fail_next:
            self.fail_next = False
            raise RuntimeError("physics exploded")
        self.steps.append((v, w, duration))
        self.pose = Pose(self.pose.x + v * duration, self.pose.y, self.pose.yaw + w * duration)
        self.time += duration
        return self._img()

    def info(self) -> dict[str, Any]:
        return {"camera": {"width": 8, "height": 6}, "map": "tiny", "nan": math.nan}


def tiny_sim() -> TinySim:
    return TinySim()


def req(cmd: str, seq: int = 1, **fields: Any) -> list[bytes]:
    h = {"proto": "vtr-sim", "version": 1, "cmd": cmd, "seq": seq, "stamp": 0.0, **fields}
    return [json.dumps(h).encode()]


BAD = [
    ([b"{oops"], "malformed JSON"),
    (req("hello", version=9), "unsupported protocol version 9"),
    (req("hello", proto="http"), "wrong protocol"),
    (req("teleport"), "unknown command 'teleport'"),
    (req("step", v=0.1, w=0.0), "missing field 'duration'"),
    (
        [b'{"proto":"vtr-sim","version":1,"cmd":"step","seq":1,"stamp":0,"v":NaN,"w":0,"duration":0.1}'],
        "non-finite",
    ),
    (req("step", v=2.0, w=0.0, duration=0.1), "v_max=0.5"),
    (req("step", v=0.0, w=3.0, duration=0.1), "w_max=1.0"),
    (req("step", v=0.1, w=0.0, duration=-1), "duration=-1"),
    (req("reset", pose={"x": 0}), "pose."),
    (req("observe") + [b"x" * 5000], "exceeds the limit of 4096 bytes"),
    (req("observe") + [b"x"], "one header frame"),
]


def test_handle_answers_every_bad_request_then_serves_a_good_one():
    sim = TinySim()
    server = SimServer(sim, ServerConfig(max_message_bytes=4096))
    for frames, fragment in BAD:
        reply = protocol.decode_reply(server.handle(frames))
        assert not reply.ok and fragment in reply.error, (fragment, reply.error)
    assert sim.steps == [] and sim.time == 0.0  # no bad request moved the robot
    reply = protocol.decode_reply(
        server.handle(protocol.encode_request("step", 5, v=0.5, w=0.0, duration=0.2))
    )
    assert reply.ok and reply.seq == 5 and reply.stamp == pytest.approx(0.2)
    assert reply.pose == pytest.approx((0.1, 0.0, 0.0)) and reply.image[0, 0, 0] == 10
    assert server.errors == len(BAD) and server.requests == len(BAD) + 1


def test_error_reply_echoes_cmd_and_seq_when_readable():
    server = SimServer(TinySim())
    reply = protocol.decode_reply(server.handle(req("step", seq=42, v=9.0, w=0.0, duration=0.1)))
    assert not reply.ok and reply.cmd == "step" and reply.seq == 42 and reply.session == server.session


def test_simulator_exception_becomes_an_error_reply():
    sim = TinySim()
    server = SimServer(sim)
    sim.fail_next = True
    reply = protocol.decode_reply(
        server.handle(protocol.encode_request("step", 1, v=0.1, w=0.0, duration=0.1))
    )
    assert not reply.ok and "physics exploded" in reply.error
    assert protocol.decode_reply(server.handle(protocol.encode_request("observe", 2))).ok


def test_lockstep_time_advances_only_on_step_and_hello_reports_the_server():
    sim = TinySim()
    server = SimServer(sim)
    hello = protocol.decode_reply(server.handle(protocol.encode_request("hello", 1)))
    assert hello.header["protocol_version"] == 1 and hello.header["camera"] == {
        "width": 8,
        "height": 6,
        "fov_deg": None,
        "height_m": None,
    }
    assert hello.header["limits"] == {"v_max": 0.5, "w_max": 1.0, "max_duration": 10.0}
    assert hello.header["info"]["nan"] is None  # NaN never reaches the wire
    for seq in range(2, 5):
        assert protocol.decode_reply(server.handle(protocol.encode_request("observe", seq))).stamp == 0.0
    server.handle(protocol.encode_request("step", 5, v=0.0, w=0.5, duration=0.3))
    assert protocol.decode_reply(server.handle(protocol.encode_request("stop", 6))).stamp == pytest.approx(
        0.3
    )
    assert server.twist == (0.0, 0.0)
    reset = protocol.decode_reply(server.handle(protocol.encode_request("reset", 7, pose=(0.5, 0.0, 0.0))))
    assert reset.stamp == 0.0 and reset.pose == (0.5, 0.0, 0.0)


def test_real_zeromq_server_keeps_serving_after_bad_requests():
    sim = TinySim()
    cfg = ServerConfig(bind="tcp://127.0.0.1:*", max_message_bytes=4096, poll_ms=20)
    with ServerThread(sim, cfg) as server:
        ctx = zmq.Context()
        sock = ctx.socket(zmq.REQ)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.RCVTIMEO, 5000)
        sock.connect(server.endpoint)
        try:
            for frames, fragment in BAD:
                sock.send_multipart(frames)
                reply = protocol.decode_reply(sock.recv_multipart())
                assert not reply.ok and fragment in reply.error
            sock.send_multipart(protocol.encode_request("step", 9, v=0.2, w=0.0, duration=0.5))
            reply = protocol.decode_reply(
                sock.recv_multipart(), expect_cmd="step", expect_seq=9, expect_shape=(6, 8)
            )
            assert reply.ok and reply.pose == pytest.approx((0.1, 0.0, 0.0))
        finally:
            sock.close()
            ctx.term()
    assert sim.steps == [(0.2, 0.0, 0.5)]


def test_server_process_shuts_down_cleanly_on_sigterm():
    handle = start_server_process(ServerConfig(bind="tcp://127.0.0.1:*", poll_ms=20), tiny_sim)
    ctx = zmq.Context()
    sock = ctx.socket(zmq.REQ)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.RCVTIMEO, 10000)
    sock.connect(handle.endpoint)
    try:
        sock.send_multipart(protocol.encode_request("observe", 1))
        assert protocol.decode_reply(sock.recv_multipart()).ok
    finally:
        sock.close()
        ctx.term()
    assert handle.terminate() == 0  # SIGTERM: the loop saw the flag and returned


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"bind": "localhost:5555"}, "no transport"),
        ({"max_message_bytes": 10}, "max_message_bytes"),
        ({"v_max": float("nan")}, "v_max"),
        ({"poll_ms": 0}, "poll_ms"),
        ({"mode": "fast"}, "mode"),
        ({"realtime_factor": 0.0}, "realtime_factor"),
        ({"max_message_bytes": 10**6, "hard_max_message_bytes": 10**5}, "hard_max_message_bytes"),
    ],
)
def test_server_config_validation(kwargs, fragment):
    with pytest.raises(ValueError, match=fragment):
        ServerConfig(**kwargs)


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_realtime_mode_keeps_driving_until_stop():
    from vtr.sim2d.server import Deferred

    sim, clock = TinySim(), FakeClock()
    server = SimServer(sim, ServerConfig(mode="realtime"), clock=clock)
    deferred = server.handle_deferred(protocol.encode_request("step", 1, v=0.5, w=0.0, duration=0.2))
    assert isinstance(deferred, Deferred) and deferred.deadline == pytest.approx(100.2)
    clock.t = 100.2
    reply = protocol.decode_reply(server.finish(deferred))
    assert reply.stamp == pytest.approx(0.2) and reply.pose[0] == pytest.approx(0.1)
    clock.t = 100.5  # no zero command yet: the robot kept moving while the client was thinking
    reply = protocol.decode_reply(server.handle(protocol.encode_request("observe", 2)))
    assert reply.stamp == pytest.approx(0.5) and reply.pose[0] == pytest.approx(0.25)
    server.handle(protocol.encode_request("stop", 3))
    clock.t = 101.5
    reply = protocol.decode_reply(server.handle(protocol.encode_request("observe", 4)))
    assert reply.stamp == pytest.approx(1.5) and reply.pose[0] == pytest.approx(
        0.25
    )  # time runs, robot still
    hello = protocol.decode_reply(server.handle(protocol.encode_request("hello", 5)))
    assert hello.header["mode"] == "realtime"


def test_realtime_server_over_zeromq_answers_steps_after_their_duration():
    sim = TinySim()
    cfg = ServerConfig(bind="tcp://127.0.0.1:*", mode="realtime", realtime_factor=10.0, poll_ms=5)
    with ServerThread(sim, cfg) as server:
        from vtr.runtime.client import SimClient

        with SimClient(server.endpoint, timeout_s=5.0) as client:
            first = client.observe()
            obs = client.step(0.5, 0.0, 1.0)  # 1 simulated second = 0.1 s of wall clock at factor 10
            client.stop()
            assert obs.stamp >= first.stamp + 1.0 and obs.pose[0] >= 0.5 - 1e-9
        assert server.server.twist == (0.0, 0.0)
