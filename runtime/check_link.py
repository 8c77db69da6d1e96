"""What the checks of `vtr check-robot` share: the raw request/reply link (one request at a time, a timeout on
each, never a hang) and the :class:`Context` the checks fill in order.

Unlike runtime.client.SimClient it sends requests as given (no client-side validation, so a step beyond the
default limits or a malformed header can be sent on purpose) and it never resends: a lost reply is a finding.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import zmq

from vtr.runtime import protocol
from vtr.runtime.contracts import CONTROL_DT
from vtr.runtime.hello import Hello
from vtr.runtime.preprocess import image_error

PASS, WARN, FAIL, SKIP = "PASS", "WARN", "FAIL", "SKIP"

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


def unannounced(replies: list[Any], field: str, section: str, absent: str) -> tuple[str, str]:
    """An optional reply field hello does not announce (docs/PROTOCOL.md, ``section``): WARN where replies carry
    it anyway (the runtime ignores it), else PASS saying what the robot goes without (``absent``)."""
    if any(r.header.get(field) is not None for r in replies):
        return WARN, (
            f"replies carry a '{field}' but hello does not announce one, so the runtime ignores it: announce it "
            f"(docs/PROTOCOL.md, '{section}')"
        )
    return PASS, absent


def announced(replies: list[Any], field: str, decode: Callable[[Any], Any]) -> list[Any]:
    """An optional reply field hello announces, decoded from every reply; CheckFailed names the reply where it
    is missing or does not decode."""
    out = []
    for reply in replies:
        if reply.header.get(field) is None:
            raise CheckFailed(f"hello announces a '{field}' but the {reply.cmd!r} reply carries no '{field}'")
        try:
            out.append(decode(reply.header[field]))
        except protocol.BadFrameError as exc:
            raise CheckFailed(f"the {reply.cmd!r} reply's {field}: {exc}") from None
    return out


def percentile_ms(times_s: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(times_s) * 1e3, q)) if times_s else float("nan")


@dataclass
class Context:
    """What the checks learn from the robot, shared between them in order."""

    link: Link
    hello: Hello | None = None
    hello_problems: dict[str, str] = field(default_factory=dict)  # hello field -> what is wrong with it
    camera: tuple[int, int] | None = None  # (height, width) announced
    limits: protocol.Limits | None = None
    dt: float = CONTROL_DT  # step duration used by the checks
    resets: bool = False
    image: np.ndarray | None = None  # the last image seen
    noise_floor: float = 0.0  # mean abs difference between two frames of a robot at rest
    model: Any = None  # the ModelMeta the image check compares the camera with (None: the trained camera's)
    stamps: list[tuple[str, float]] = field(default_factory=list)  # (cmd, stamp) since the last reset
    stamp_problems: list[str] = field(default_factory=list)

    def note_stamp(self, reply: protocol.Reply) -> None:
        if reply.stamp is None:
            return
        if reply.cmd == "reset":
            self.stamps.clear()
        elif self.stamps:
            cmd0, before = self.stamps[-1]
            if reply.stamp < before:
                self.stamp_problems.append(f"{reply.cmd!r} stamp {reply.stamp} < previous {cmd0!r} {before}")
            elif reply.cmd == "step" and reply.stamp <= before:
                self.stamp_problems.append(f"a step did not advance the stamp ({before} -> {reply.stamp})")
        self.stamps.append((str(reply.cmd), reply.stamp))

    def ask(self, cmd: str, **fields: Any) -> protocol.Reply:
        """A well-formed request whose ok reply must decode; CheckFailed otherwise."""
        reply = self.link.ask(cmd, **fields)
        if not reply.ok:
            raise CheckFailed(f"{cmd!r} was refused: {reply.error}")
        self.note_stamp(reply)
        if reply.image is not None:
            self._check_shape(reply.image)
            self.image = reply.image
        return reply

    def _check_shape(self, image: np.ndarray) -> None:
        if self.camera is not None and image.shape[:2] != self.camera:
            raise CheckFailed(
                f"image is {image.shape[0]}x{image.shape[1]} but hello announced {self.camera[0]}x{self.camera[1]}"
            )

    def step(self, v: float, w: float) -> protocol.Reply:
        return self.ask("step", v=v, w=w, duration=self.dt)


Check = Callable[[Context], tuple[str, str]]
