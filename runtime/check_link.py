"""The raw request/reply link `vtr check-robot` uses: one request at a time, a timeout on each, never a hang.

Unlike runtime.client.SimClient it sends requests as given (no client-side validation, so a step beyond the
default limits or a malformed header can be sent on purpose) and it never resends: a lost reply is a finding.
"""

from __future__ import annotations

import json
import time
from typing import Any

import numpy as np
import zmq

from vtr.runtime import protocol
from vtr.runtime.preprocess import image_error

_ECHO_HINT = " (every reply, an error reply too, carries proto, version, cmd, seq, ok and stamp)"


class CheckFailed(Exception):
    """A check found a defect; the message says what to fix."""


class Link:
    """A REQ socket with a per-request timeout; a timed-out socket is rebuilt (ZeroMQ's REQ is stuck then)."""

    def __init__(self, endpoint: str, timeout_s: float) -> None:
        self.endpoint = endpoint
        self.timeout_s = float(timeout_s)
        self.seq = 0
        self.last_rtt_s = 0.0
        self._ctx = zmq.Context()
        self._sock: zmq.Socket | None = None

    def _socket(self) -> zmq.Socket:
        if self._sock is None:
            self._sock = self._ctx.socket(zmq.REQ)
            self._sock.setsockopt(zmq.LINGER, 0)
            self._sock.setsockopt(zmq.MAXMSGSIZE, protocol.MAX_MESSAGE_BYTES)
            self._sock.connect(self.endpoint)
        return self._sock

    def _drop(self) -> None:
        if self._sock is not None:
            self._sock.close(linger=0)
            self._sock = None

    def close(self) -> None:
        self._drop()
        self._ctx.term()

    def send(self, frames: list[bytes]) -> list[bytes] | None:
        """Send frames, wait up to the timeout; None when no reply came (the socket is then rebuilt)."""
        sock = self._socket()
        t0 = time.perf_counter()
        sock.send_multipart(frames)
        if not sock.poll(int(self.timeout_s * 1000), zmq.POLLIN):
            self._drop()
            return None
        reply = sock.recv_multipart()
        self.last_rtt_s = time.perf_counter() - t0
        return reply

    def ask(self, cmd: str, **fields: Any) -> protocol.Reply:
        """A well-formed request; the reply (ok or error) decoded, or CheckFailed naming the defect."""
        self.seq += 1
        header = {"proto": protocol.PROTO, "version": protocol.VERSION, "cmd": cmd, "seq": self.seq}
        header.update(stamp=time.time(), **fields)
        frames = self.send([json.dumps(header).encode("utf-8")])
        if frames is None:
            raise CheckFailed(
                f"no reply to {cmd!r} within {self.timeout_s} s: a bridge must answer every request"
            )
        try:
            reply = protocol.decode_reply(frames)
        except protocol.BadFrameError as exc:
            raise CheckFailed(f"the reply to {cmd!r} does not decode: {exc}{_ECHO_HINT}") from None
        if reply.seq != self.seq or reply.cmd != cmd:
            raise CheckFailed(
                f"the reply to {cmd!r} seq {self.seq} names cmd {reply.cmd!r} seq {reply.seq!r}: echo both"
            )
        if reply.ok:
            try:  # the strict checks an ok reply gets in the runtime's client
                protocol.decode_reply(frames, expect_cmd=cmd, expect_seq=self.seq)
            except protocol.BadFrameError as exc:
                raise CheckFailed(f"the reply to {cmd!r} does not decode: {exc}{_ECHO_HINT}") from None
        elif reply.error is None or not reply.error.strip():
            raise CheckFailed(f"{cmd!r} got ok: false without an 'error' text saying why")
        return reply

    def raw_reply(self, frames: list[bytes], what: str) -> protocol.Reply:
        """Send arbitrary frames; the decoded reply, or CheckFailed when it is missing or malformed."""
        reply_frames = self.send(frames)
        if reply_frames is None:
            raise CheckFailed(
                f"no reply to a request with a {what} within {self.timeout_s} s: answer every request, "
                "bad ones with ok: false and an error"
            )
        try:
            return protocol.decode_reply(reply_frames)
        except protocol.BadFrameError as exc:
            raise CheckFailed(
                f"the error reply to a request with a {what} does not decode: {exc}{_ECHO_HINT}"
            ) from None

    def stop_quietly(self) -> None:
        """A last zero command; the robot may be the thing that failed, so nothing here raises."""
        try:
            self.ask("stop")
        except (CheckFailed, zmq.ZMQError):
            pass


def image_diff(a: np.ndarray, b: np.ndarray) -> float:
    """Mean absolute pixel difference (0..255); images of different shapes count as entirely different."""
    if a.shape != b.shape:
        return 255.0
    return image_error(a, b)


def percentile_ms(times_s: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(times_s) * 1e3, q)) if times_s else float("nan")
