"""Server faults: the realtime watchdog, the session guard, errors anywhere in a request, what hello tells."""

from __future__ import annotations

import json

import numpy as np
import pytest
import zmq
from test_server_protocol import FakeClock, TinySim

from vtr.runtime import protocol
from vtr.runtime.hello import parse_hello
from vtr.sim2d.server import ServerConfig, ServerThread, SimServer


def step_at(server: SimServer, clock: FakeClock, v: float, duration: float, seq: int = 1) -> None:
    deferred = server.handle_deferred(protocol.encode_request("step", seq, v=v, w=0.0, duration=duration))
    clock.t = deferred.deadline
    assert protocol.decode_reply(server.finish(deferred)).ok


def x_at(server: SimServer, clock: FakeClock, t: float, seq: int = 99) -> float:
    clock.t = t
    return protocol.decode_reply(server.handle(protocol.encode_request("observe", seq))).pose[0]


def test_realtime_watchdog_stops_a_robot_whose_client_went_silent():
    sim, clock = TinySim(), FakeClock()
    server = SimServer(sim, ServerConfig(mode="realtime", cmd_vel_timeout=0.5), clock=clock)
    step_at(server, clock, 0.5, 0.1)  # arrives at t=100.0, answered at 100.1; then the client dies
    assert x_at(server, clock, 100.4) == pytest.approx(0.2)  # still driving 0.4 s after the command
    assert x_at(server, clock, 103.0) == pytest.approx(0.25)  # stopped 0.5 s after it: 0.5 m/s x 0.5 s
    assert server.watchdog_stops == 1 and server.twist == (0.0, 0.0)


def test_watchdog_lets_a_long_step_finish_and_zero_disables_it():
    sim, clock = TinySim(), FakeClock()
    server = SimServer(sim, ServerConfig(mode="realtime", cmd_vel_timeout=0.5), clock=clock)
    step_at(server, clock, 0.5, 2.0)
    assert x_at(server, clock, 110.0) == pytest.approx(1.0)  # the whole 2 s step, then zero
    sim2, clock2 = TinySim(), FakeClock()
    off = SimServer(sim2, ServerConfig(mode="realtime", cmd_vel_timeout=0.0), clock=clock2)
    step_at(off, clock2, 0.5, 0.1)
    assert x_at(off, clock2, 102.0) == pytest.approx(1.0)  # disabled: the last twist drives on
    assert (
        protocol.decode_reply(off.handle(protocol.encode_request("hello", 1))).header["cmd_vel_timeout"]
        == 0.0
    )


def test_a_step_for_another_session_is_refused_and_not_executed():
    sim = TinySim()
    server = SimServer(sim)
    step = protocol.encode_request("step", 1, v=0.3, w=0.0, duration=0.1, session="someone-else")
    reply = protocol.decode_reply(server.handle(step))
    assert not reply.ok and reply.code == "session_mismatch" and "not executed" in reply.error
    assert sim.steps == []
    stop = protocol.decode_reply(server.handle(protocol.encode_request("stop", 2, session="someone-else")))
    assert stop.ok  # a zero command is always welcome
    mine = protocol.encode_request("step", 3, v=0.3, w=0.0, duration=0.1, session=server.session)
    assert protocol.decode_reply(server.handle(mine)).ok and len(sim.steps) == 1


class BrokenSim(TinySim):
    def observe(self):
        return np.zeros((2, 2), dtype=np.float64)  # not an image: encoding the reply fails

    def info(self):
        raise MemoryError("out of memory in info()")


def test_any_exception_while_handling_a_request_is_an_error_reply_with_a_stamp(monkeypatch):
    server = SimServer(BrokenSim())
    for cmd, fragment in (("observe", "image must be"), ("hello", "out of memory")):
        reply = protocol.decode_reply(server.handle(protocol.encode_request(cmd, 4)))
        assert not reply.ok and fragment in reply.error and reply.seq == 4 and reply.stamp == 0.0

    def explode(*args, **kwargs):
        raise RecursionError("deep")

    monkeypatch.setattr(protocol, "decode_request", explode)
    reply = protocol.decode_reply(server.handle([b'{"cmd":"stop","seq":5}']))
    assert not reply.ok and reply.code == "robot_error" and reply.cmd == "stop" and reply.seq == 5


def test_hello_follows_the_schema_and_names_the_map_not_its_path():
    class MapSim(TinySim):
        def info(self):
            return {
                "map": "house",
                "map_source": "/home/someone/secret/house.json",
                "camera": {"width": 8, "height": 6, "fov_deg": 90.0, "camera_height": 0.3},
                "physics_dt": 0.02,
            }

    server = SimServer(MapSim(), ServerConfig(mode="realtime"))
    frames = server.handle(protocol.encode_request("hello", 1))
    assert b"/home/someone" not in frames[0]
    hello = parse_hello(protocol.decode_reply(frames))
    assert hello.map == "house" and hello.camera.height_m == 0.3 and hello.camera.fov_deg == 90.0
    assert hello.mode == "realtime" and hello.cmd_vel_timeout == 0.5 and hello.dt == 0.02


def test_a_peer_sending_more_than_the_hard_cap_is_cut_off_and_others_are_served():
    cfg = ServerConfig(
        bind="tcp://127.0.0.1:*", max_message_bytes=4096, hard_max_message_bytes=8192, poll_ms=10
    )
    with ServerThread(TinySim(), cfg) as server:
        ctx = zmq.Context()
        hostile, good = ctx.socket(zmq.DEALER), ctx.socket(zmq.REQ)
        for sock in (hostile, good):
            sock.setsockopt(zmq.LINGER, 0)
            sock.connect(server.endpoint)
        try:
            hostile.send_multipart([b"", json.dumps({"x": "a" * 100_000}).encode()])
            good.send_multipart(protocol.encode_request("observe", 1))
            assert good.poll(5000) and protocol.decode_reply(good.recv_multipart()).ok
            assert not hostile.poll(200)  # never answered: ZeroMQ dropped the connection
        finally:
            hostile.close()
            good.close()
            ctx.term()


def test_a_contact_while_coasting_between_requests_is_reported_in_realtime():
    """In realtime the twist drives on between requests, and the next request advances the robot first. A
    contact in that coasting (the robot brushing a wall, then clear of it) was overwritten by the later
    advances, and the runtime's stop on contact never heard of it."""

    class Brushing(TinySim):
        def step(self, v: float, w: float, duration: float) -> np.ndarray:
            image = super().step(v, w, duration)
            self.collided = 0.1 < self.pose.x < 0.2  # touching the wall only along this stretch
            return image

    sim, clock = Brushing(), FakeClock()
    server = SimServer(
        sim, ServerConfig(mode="realtime", cmd_vel_timeout=0.0, max_step_duration=0.1), clock=clock
    )
    step_at(server, clock, 0.5, 0.1)  # x = 0.05 at the reply: no contact yet
    clock.t = 100.7  # coasting at 0.5 m/s: through the touching stretch and out of it (x = 0.35)
    reply = protocol.decode_reply(server.handle(protocol.encode_request("observe", 2)))
    assert reply.pose[0] == pytest.approx(0.35) and not sim.collided  # the last chunk is clear ...
    assert reply.collided  # ... but the robot touched the wall on its way
    clock.t = 100.8
    assert not protocol.decode_reply(server.handle(protocol.encode_request("observe", 3))).collided  # once
