"""ZeroMQ client for the simulator (or a robot bridge speaking the same protocol): a ``Robot`` over the wire.

Reliability follows the Lazy Pirate pattern (ZeroMQ Guide, ch. 4): send on a REQ socket, poll for the
reply with a timeout; on timeout the socket is stuck mid-exchange, so close it with LINGER=0, open a
fresh one and resend; after ``retries`` attempts give up with a :class:`~runtime.robot.RobotError`.

Note that resending a ``step`` whose reply was lost may apply it twice; on a lockstep simulator this
moves the robot one extra control step, which the visual controller absorbs.

Every reply is validated by :mod:`runtime.protocol`; a reply that fails (wrong shape, encoding,
truncated pixels, unknown version, stale seq, a stamp older than the last one of the same server
session) raises :class:`~runtime.protocol.BadFrameError` and increments :attr:`SimClient.bad_frames`.
"""

from __future__ import annotations

import time
from typing import Any

import zmq

from vtr.runtime import protocol
from vtr.runtime.protocol import BadFrameError, Reply
from vtr.runtime.robot import Observation, RobotError


class SimClient:
    """Robot over ZeroMQ. ``expect_shape`` (H, W) rejects images of any other size."""

    def __init__(
        self,
        endpoint: str,
        timeout_s: float = 2.0,
        retries: int = 3,
        expect_shape: tuple[int, int] | None = None,
        max_message_bytes: int = protocol.MAX_MESSAGE_BYTES,
    ) -> None:
        if timeout_s <= 0:
            raise ValueError(f"timeout_s must be > 0, got {timeout_s}")
        if retries < 1:
            raise ValueError(f"retries must be >= 1, got {retries}")
        self.endpoint = endpoint
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self.expect_shape = expect_shape
        self.max_message_bytes = max_message_bytes
        #: Replies rejected by validation.
        self.bad_frames = 0
        #: Times a reply did not arrive in time and the socket was rebuilt.
        self.timeouts = 0
        #: Times the server's session token changed (it restarted).
        self.session_changes = 0
        self.session: str | None = None
        self.last_bad_frame: str | None = None
        self._last_stamp: float | None = None
        #: The last exchange's round trip (send to reply received) and validation time, in milliseconds.
        self.last_timing_ms: dict[str, float] = {}
        self._seq = 0
        self._ctx = zmq.Context()
        self._sock: zmq.Socket | None = None

    # ------------------------------------------------------------------ socket management
    def _open(self) -> zmq.Socket:
        sock = self._ctx.socket(zmq.REQ)
        sock.setsockopt(zmq.LINGER, 0)
        sock.connect(self.endpoint)
        return sock

    def _drop(self) -> None:
        if self._sock is not None:
            self._sock.close(linger=0)
            self._sock = None

    def close(self) -> None:
        self._drop()
        self._ctx.term()

    def __enter__(self) -> SimClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _exchange(self, cmd: str, **fields: Any) -> Reply:
        """Send one request, Lazy-Pirate style, and return its validated reply."""
        for _ in range(self.retries):
            self._seq += 1
            seq = self._seq
            request = protocol.encode_request(cmd, seq, stamp=time.time(), **fields)
            if self._sock is None:
                self._sock = self._open()
            t0 = time.perf_counter()
            try:
                self._sock.send_multipart(request)
                ready = self._sock.poll(int(self.timeout_s * 1000), zmq.POLLIN)
                frames = self._sock.recv_multipart() if ready else None
            except BaseException:
                # interrupted mid-exchange (e.g. KeyboardInterrupt): the REQ socket now waits for a reply
                # that nobody will read, so the zero command that follows needs a fresh socket
                self._drop()
                raise
            if frames is not None:
                t1 = time.perf_counter()
                reply = self._validate(frames, cmd, seq)
                self.last_timing_ms = {"receive": (t1 - t0) * 1e3, "decode": (time.perf_counter() - t1) * 1e3}
                return reply
            self.timeouts += 1
            self._drop()  # a REQ socket that timed out cannot send again: rebuild it
        raise RobotError(
            f"no reply from {self.endpoint} to {cmd!r} after {self.retries} tries of {self.timeout_s} s; "
            "is the simulator server (`vtr sim serve`) running?"
        )

    def _validate(self, frames: list[bytes], cmd: str, seq: int) -> Reply:
        try:
            reply = protocol.decode_reply(
                frames,
                expect_cmd=cmd,
                expect_seq=seq,
                expect_shape=self.expect_shape,
                max_message_bytes=self.max_message_bytes,
            )
            if reply.ok:
                self._check_stamp(reply)
        except BadFrameError as exc:
            self.bad_frames += 1
            self.last_bad_frame = str(exc)
            raise
        if not reply.ok:
            raise RobotError(f"{self.endpoint} refused {cmd!r}: {reply.error}")
        return reply

    def _check_stamp(self, reply: Reply) -> None:
        if reply.session != self.session:
            if self.session is not None:
                self.session_changes += 1
            self.session = reply.session
            self._last_stamp = None
        if reply.cmd == "reset":
            self._last_stamp = None
        assert reply.stamp is not None
        if self._last_stamp is not None and reply.stamp < self._last_stamp:
            raise BadFrameError(
                f"stale frame: stamp {reply.stamp} is older than the last one, {self._last_stamp}"
            )
        self._last_stamp = reply.stamp

    @staticmethod
    def _observation(reply: Reply) -> Observation:
        assert reply.image is not None and reply.stamp is not None
        return Observation(image=reply.image, stamp=reply.stamp, pose=reply.pose, collided=reply.collided)

    # ------------------------------------------------------------------ the Robot protocol
    def hello(self) -> dict[str, Any]:
        """Protocol version, camera, limits and simulated time of the server (the reply header)."""
        return dict(self._exchange("hello").header)

    def reset(self, pose: tuple[float, float, float] | None = None, seed: int | None = None) -> Observation:
        return self._observation(self._exchange("reset", pose=pose, seed=seed))

    def observe(self) -> Observation:
        return self._observation(self._exchange("observe"))

    def step(self, v: float, w: float, duration: float) -> Observation:
        return self._observation(self._exchange("step", v=float(v), w=float(w), duration=float(duration)))

    def stop(self) -> None:
        self._exchange("stop")
