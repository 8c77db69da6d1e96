"""Test doubles for the link benchmarks: a scripted robot that records when each command arrives, a policy
that always drives, and a route the robot never reaches (so a repeat runs until the fault under test).

The fake robot follows docs/PROTOCOL.md (ROUTER socket, session token, the session guard on motion
commands) and lets a ``behaviour`` decide each reply: good, broken, duplicated, late or none.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import zmq

from vtr.runtime import protocol

SIZE = 16  # image side of the fake robot: small, the link is what is measured


@dataclass
class Arrival:
    """One request as the robot saw it: monotonic arrival time and the decoded request (None: undecodable)."""

    t: float
    req: protocol.Request | None
    session: str  # the robot's session when it arrived


def good_reply(robot: FakeRobot, req: protocol.Request) -> list[bytes]:
    """The reply a correct robot gives (also refusing motion commands meant for another session)."""
    if req.session is not None and req.session != robot.session and req.cmd in protocol.GUARDED_COMMANDS:
        return protocol.encode_error(
            "session mismatch", req.cmd, req.seq, robot.session, robot.clock, "session_mismatch"
        )
    if req.cmd == "step":
        robot.clock += req.fields["duration"]
        robot.executed_steps.append((robot.session, req.fields["v"], req.fields["w"]))
    if req.cmd in protocol.IMAGE_COMMANDS:
        image = np.full((SIZE, SIZE, 3), 200, dtype=np.uint8)
        return protocol.encode_image_reply(
            req.cmd, req.seq, robot.session, robot.clock, image, (robot.pose_x, 0.0, 0.0)
        )
    extra = {}
    if req.cmd == "hello":
        extra = {
            "protocol_version": 1,
            "camera": {"width": SIZE, "height": SIZE, "fov_deg": 90.0, "height_m": 0.3},
            "limits": protocol.Limits().to_dict(),
            "dt": 0.02,
            "mode": "lockstep",
        }
    return protocol.encode_ok(req.cmd, req.seq, robot.session, robot.clock, **extra)


Behaviour = Callable[["FakeRobot", protocol.Request], list[list[bytes]]]


def honest(robot: FakeRobot, req: protocol.Request) -> list[list[bytes]]:
    return [good_reply(robot, req)]


@dataclass
class FakeRobot:
    """A robot bridge in a thread. ``behaviour(robot, request)`` returns the replies to send (0, 1 or more)."""

    behaviour: Behaviour = honest
    bind: str = "tcp://127.0.0.1:*"
    session: str = field(default_factory=lambda: uuid.uuid4().hex[:12])
    clock: float = 0.0
    pose_x: float = 0.0
    mute: bool = False
    arrivals: list[Arrival] = field(default_factory=list)
    executed_steps: list[tuple[str, float, float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._ctx = zmq.Context()
        self._sock = self._ctx.socket(zmq.ROUTER)
        self._sock.setsockopt(zmq.LINGER, 0)
        self._sock.bind(self.bind)
        self.endpoint = self._sock.getsockopt_string(zmq.LAST_ENDPOINT)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            if not self._sock.poll(2):
                continue
            ident, *frames = self._sock.recv_multipart()
            envelope, body = frames[:1], frames[1:]
            try:
                req: protocol.Request | None = protocol.decode_request(body, None)
            except protocol.ProtocolError:
                req = None
            self.arrivals.append(Arrival(time.monotonic(), req, self.session))
            if req is None:
                continue
            for reply in self.behaviour(self, req):
                self._sock.send_multipart([ident, *envelope, *reply])

    def restart(self) -> None:
        """A reboot: same address, new session, clock from zero."""
        self.close()
        self.session, self.clock = uuid.uuid4().hex[:12], 0.0
        self.bind = self.endpoint
        self.__post_init__()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        self._sock.close(linger=0)
        self._ctx.term()

    def commands(self) -> list[Arrival]:
        return [a for a in self.arrivals if a.req is not None]


class DrivingPolicy:
    """Always (v, w) = (0.2, 0.1): a stand-in for VelocityNet (the link, not the network, is measured)."""

    image_shape = (SIZE, SIZE)
    nonfinite_count = 0

    class meta:  # noqa: N801  (attribute access like OnnxPolicy.meta.dt)
        dt = 0.1

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        return np.array([[0.2, 0.2], [0.1, 0.1]], dtype=np.float32)


def unreachable_route() -> Any:
    """A route of dark images: the robot's bright view never matches, so the repeat never finishes."""
    from vtr.runtime.route import Route

    n = 4
    images = np.zeros((n, SIZE, SIZE, 3), dtype=np.uint8)
    images[:, :, : SIZE // 2] = np.arange(n, dtype=np.uint8)[:, None, None, None] * 20
    return Route(images=images, poses=np.zeros((n, 3)), commands=np.zeros((n, 2)), name="unreachable")
