"""ZeroMQ client for the simulator or a robot bridge (docs/PROTOCOL.md): a ``Robot`` over the wire.

Socket: a DEALER with explicit ``seq`` matching, not the Lazy Pirate REQ. A REQ socket pairs "the next
message" with "the current request", so one duplicated reply leaves it one reply behind for good, and it
must be rebuilt after every fault. Here each reply is matched to its request by ``seq``: a reply to an
earlier request (late or duplicated) is counted in :attr:`SimClient.stale_replies` and skipped while the
wait goes on; a malformed reply, or one for no request we sent, is counted in :attr:`bad_frames` and
raised as :class:`BadFrameError`, and the next exchange starts clean with a new ``seq``. No fault
outlives one reply. The socket is rebuilt (LINGER=0) only after a timeout, which drops any request
still queued for a peer that went away, so a rebooted robot never receives a command from before. A
socket monitor notices a dropped connection; the next ``reset``/``step`` is then preceded by a ``hello``
that reveals a rebooted robot before any motion command reaches it (and the server refuses a motion
command naming another session, should one slip through).

Timeouts never resend a motion command. A ``step`` waits ``duration + timeout_s``; when nothing comes,
the first thing sent is a ``stop``. If the stop is answered the step raises BadFrameError (the robot is
stopped, the link is alive); if not, :class:`LinkLost`. Only ``hello``, ``observe`` and ``stop`` are
retried. ``cancel`` (the run's stop event, set by Ctrl-C/SIGTERM) ends any wait within ``slice_s``.

Stamps are judged per robot session: a stamp older than the last accepted one is stale; one further ahead
than the wall clock allows (``duration`` + elapsed wall time x the announced rate + 1 s) is from the
future; either is rejected without moving the reference, so one outlier costs one frame. ``reset``
restarts the clock. A new session token, confirmed by a ``hello`` that carries it too, means the robot
restarted: :class:`RobotRestarted` (one corrupt session field is one bad frame, not a restart).

A range scan in a reply is read (checked against the scanner ``hello`` announced) once :meth:`handshake`
has run, and travels on the :class:`Observation`; before it, or from a robot without one, ``scan`` is None.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import zmq

from vtr.runtime import protocol
from vtr.runtime.address import check_endpoint
from vtr.runtime.frame import Frame
from vtr.runtime.hello import Hello, parse_hello
from vtr.runtime.protocol import BadFrameError, Limits, Reply
from vtr.runtime.resample import CameraMapping
from vtr.runtime.robot import Interrupted, LinkLost, MissedReply, Observation, RobotError, RobotRestarted

#: Commands that are safe to send again after a missed reply (they move nothing).
RETRYABLE = ("hello", "observe", "stop")
#: Slack on the "stamp from the future" bound, in robot-clock seconds.
FUTURE_SLACK_S = 1.0


class SimClient:
    """Robot over ZeroMQ. ``expect_shape`` (H, W) rejects images of any other size.

    ``timeout_s`` is the reply wait beyond a step's own duration (the margin that bounds how late the
    stop comes when the robot goes silent: ``dt + timeout_s``, 0.4 s by default); ``setup_timeout_s``
    is the wait for ``hello`` and ``reset``, which may rebuild a world.
    """

    def __init__(
        self,
        endpoint: str,
        timeout_s: float = 0.3,
        retries: int = 3,
        expect_shape: tuple[int, int] | None = None,
        max_message_bytes: int = protocol.MAX_MESSAGE_BYTES,
        setup_timeout_s: float = 5.0,
        cancel: threading.Event | None = None,
        slice_s: float = 0.02,
    ) -> None:
        if not timeout_s > 0 or not setup_timeout_s > 0:
            raise ValueError(f"timeout_s and setup_timeout_s must be > 0, got {timeout_s}, {setup_timeout_s}")
        if retries < 1:
            raise ValueError(f"retries must be >= 1, got {retries}")
        check_endpoint(endpoint)
        self.endpoint = endpoint
        self.timeout_s = float(timeout_s)
        self.setup_timeout_s = float(setup_timeout_s)
        self.retries = int(retries)
        self.expect_shape = expect_shape
        self.max_message_bytes = int(max_message_bytes)
        self.cancel = cancel or threading.Event()
        self.slice_s = float(slice_s)
        #: Replies rejected by validation (malformed, wrong seq/cmd/shape, stale or future stamp).
        self.bad_frames = 0
        #: Replies to an earlier request (late or duplicated), skipped.
        self.stale_replies = 0
        #: Waits that ended without a reply (the socket was rebuilt each time).
        self.timeouts = 0
        #: Times the server's session token changed (it restarted).
        self.session_changes = 0
        self.session: str | None = None
        self.last_bad_frame: str | None = None
        #: What the robot announced (set by :meth:`handshake`); its limits check every step before sending.
        self.hello_info: Hello | None = None
        #: How the robot's frames become the model's input (:meth:`map_frames`); None: used as they come.
        self.mapping: CameraMapping | None = None
        #: The last exchange's round trip (send to reply received), validation and (with a mapping that is not
        #: the identity) resampling time, in milliseconds.
        self.last_timing_ms: dict[str, float] = {}
        self._last_stamp: float | None = None
        self._last_stamp_wall = 0.0
        self._seq = 0
        self._confirming = False  # inside the hello that checks a session change
        self._ctx = zmq.Context()
        self._sock: zmq.Socket | None = None
        self._monitor: zmq.Socket | None = None

    @property
    def limits(self) -> Limits | None:
        return None if self.hello_info is None else self.hello_info.limits

    # ------------------------------------------------------------------ socket management
    def _socket(self) -> zmq.Socket:
        if self._sock is None:
            sock = self._ctx.socket(zmq.DEALER)
            sock.setsockopt(zmq.LINGER, 0)
            sock.setsockopt(zmq.MAXMSGSIZE, self.max_message_bytes)  # a 300 MiB reply never reaches memory
            # disconnects (a robot that died or rebooted) are noticed before the next motion command
            self._monitor = sock.get_monitor_socket(zmq.EVENT_DISCONNECTED)
            sock.connect(self.endpoint)
            self._sock = sock
        return self._sock

    def _drop(self) -> None:
        if self._sock is not None:
            self._sock.disable_monitor()
            self._monitor.close(linger=0)
            self._sock.close(linger=0)
            self._sock = None

    def _peer_dropped(self) -> bool:
        """Whether the connection to the robot dropped since the last look (drains the monitor)."""
        dropped = False
        while self._sock is not None and self._monitor.poll(0):
            self._monitor.recv_multipart()
            dropped = True
        return dropped

    def close(self) -> None:
        self._drop()
        self._ctx.term()

    def __enter__(self) -> SimClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ one exchange
    def _exchange(self, cmd: str, **fields: Any) -> Reply:
        """Send one request and return its validated reply (see the module docstring for faults)."""
        for attempt in range(1, self.retries + 1):
            reply = self._attempt(cmd, fields)
            if reply is not None:
                return reply
            # timed out: the request may be queued for a dead peer; drop it with the socket
            self.timeouts += 1
            self._drop()
            if cmd != "stop":
                stopped = self._stop_after_timeout()
                if cmd not in RETRYABLE:
                    wait = self._wait_s(cmd, fields)
                    if stopped:
                        why = f"no reply to {cmd!r} within {wait:.2f} s; the robot was sent a stop"
                        self._reject(why, MissedReply(why, wait))
                    raise LinkLost(
                        f"no reply from {self.endpoint} to {cmd!r} within {wait:.2f} s, nor to the stop sent after it"
                    )
            if attempt == self.retries:
                break
        raise LinkLost(
            f"no reply from {self.endpoint} to {cmd!r} after {self.retries} tries; "
            "is the robot bridge or the simulator (`vtr sim serve`) running?"
        )

    def _wait_s(self, cmd: str, fields: dict[str, Any]) -> float:
        if cmd in ("hello", "reset"):
            return self.setup_timeout_s
        return float(fields.get("duration", 0.0)) + self.timeout_s

    def _attempt(self, cmd: str, fields: dict[str, Any]) -> Reply | None:
        """Send once and wait; the reply, or None on timeout. Raises on a bad reply or a cancel."""
        guard = self.session if cmd in protocol.GUARDED_COMMANDS else None
        if guard is not None and self._peer_dropped():
            # the connection dropped: a hello says whether the same robot is back (else RobotRestarted)
            self._attempt("hello", {})
            guard = self.session
        self._seq += 1
        seq = self._seq
        frames = protocol.encode_request(cmd, seq, time.time(), self.limits, session=guard, **fields)
        sock = self._socket()
        t0 = time.perf_counter()
        deadline = time.monotonic() + self._wait_s(cmd, fields)
        try:
            sock.send_multipart([b"", *frames], zmq.NOBLOCK)
        except zmq.Again:
            return None
        try:
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return None
                if cmd != "stop" and self.cancel.is_set():
                    self._drop()
                    raise Interrupted(f"{cmd!r} abandoned: the run was asked to stop")
                if not sock.poll(int(max(1, min(remaining, self.slice_s) * 1000)), zmq.POLLIN):
                    continue
                raw = sock.recv_multipart(zmq.NOBLOCK)
                t1 = time.perf_counter()
                reply = self._match(raw, cmd, seq, fields)
                if reply is not None:
                    self.last_timing_ms = {
                        "receive": (t1 - t0) * 1e3,
                        "decode": (time.perf_counter() - t1) * 1e3,
                    }
                    return reply
        except KeyboardInterrupt:
            self._drop()  # the zero command that follows needs a socket without this pending request
            raise

    def _stop_after_timeout(self) -> bool:
        """Stops on a fresh socket, up to ``retries``; True as soon as one is answered, even badly or with
        a refusal (the robot is there). A new session raises RobotRestarted."""
        for _ in range(self.retries):
            try:
                if self._attempt("stop", {}) is not None:
                    return True
            except RobotRestarted:
                raise
            except (RobotError, BadFrameError):
                return True
            self.timeouts += 1
            self._drop()
        return False

    def _reject(self, why: str, error: BadFrameError | None = None) -> None:
        self.bad_frames += 1
        self.last_bad_frame = why
        raise error if error is not None else BadFrameError(why)

    def _match(self, raw: list[bytes], cmd: str, seq: int, fields: dict[str, Any]) -> Reply | None:
        """A reply for ``seq``, or None for one to skip (an earlier request's); raises on a bad one."""
        if len(raw) < 2 or raw[0] != b"":
            self._reject(f"reply without the empty delimiter frame ({len(raw)} frames)")
        frames = raw[1:]
        try:
            reply = protocol.decode_reply(
                frames,
                expect_shape=self.expect_shape,
                max_message_bytes=self.max_message_bytes,
                expect_scan=None if self.hello_info is None else self.hello_info.scan,
                expect_twist=self.hello_info is not None and self.hello_info.twist is not None,
            )
        except BadFrameError as exc:
            _, peeked = protocol.peek_cmd_seq(frames)
            if peeked is not None and peeked < seq:
                self.stale_replies += 1  # a broken reply to an old request: it cannot affect this one
                return None
            self._reject(str(exc))
        if reply.seq is not None and reply.seq < seq:
            self.stale_replies += 1
            return None
        if reply.seq is not None and reply.seq != seq:
            self._reject(f"reply has seq {reply.seq}, but the last request sent was {seq}")
        if reply.cmd is not None and reply.cmd != cmd:
            self._reject(f"reply is for command {reply.cmd!r}, expected {cmd!r}")
        self._check_session(reply)
        if not reply.ok:
            raise RobotError(f"{self.endpoint} refused {cmd!r}: {reply.error}")
        self._check_stamp(reply, float(fields.get("duration", 0.0)))
        return reply

    def _check_session(self, reply: Reply) -> None:
        """A reply from another session: the robot restarted, or the reply is corrupt. A ``hello`` tells
        which: the same new session again confirms the restart (RobotRestarted), the old one makes this
        reply one bad frame."""
        if reply.session is None or reply.session == self.session or self._confirming:
            return
        previous = self.session
        if previous is None:
            self.session, self._last_stamp = reply.session, None
            return
        self._confirming = True
        try:
            confirm = self._attempt("hello", {})
        except (RobotError, BadFrameError):
            confirm = None
        finally:
            self._confirming = False
        if confirm is not None and confirm.session == previous:
            self._reject(f"reply from session {reply.session}, but the robot is still session {previous}")
        self.session = confirm.session if confirm is not None and confirm.session else reply.session
        self._last_stamp = None
        self.session_changes += 1
        raise RobotRestarted(
            f"robot restarted: session {previous} became {self.session}; it is not where the run left it"
        )

    def _check_stamp(self, reply: Reply, duration: float) -> None:
        assert reply.stamp is not None
        now = time.monotonic()
        last = self._last_stamp
        if reply.cmd != "reset" and last is not None:
            if reply.stamp < last:
                self._reject(f"stale frame: stamp {reply.stamp} is older than the last accepted one, {last}")
            rate = 1.0 if self.hello_info is None else max(1.0, self.hello_info.realtime_factor)
            bound = last + duration + (now - self._last_stamp_wall) * rate + FUTURE_SLACK_S
            if reply.stamp > bound:
                self._reject(
                    f"frame from the future: stamp {reply.stamp} is past {bound:.3f}, the most the clock can have run"
                )
        self._last_stamp, self._last_stamp_wall = reply.stamp, now

    def map_frames(self, mapping: CameraMapping) -> None:
        """From now on expect images of the mapping's source size (the camera hello announced) and hand them
        on mapped to the model's input (runtime.resample): once, here, where frames enter."""
        self.mapping, self.expect_shape = mapping, mapping.source

    def _mapped_observation(self, reply: Reply) -> Observation:
        """:meth:`_observation` with this client's mapping, its time in ``last_timing_ms["resample"]``."""
        if self.mapping is None or self.mapping.identity:
            return self._observation(reply)
        t0 = time.perf_counter()
        obs = self._observation(reply, self.mapping)
        self.last_timing_ms["resample"] = (time.perf_counter() - t0) * 1e3
        return obs

    @staticmethod
    def _observation(reply: Reply, mapping: CameraMapping | None = None) -> Observation:
        """The decoded reply as an observation; its frame is the decoder's image (checked there: the trust
        boundary), mapped to the model's input by ``mapping`` (:meth:`map_frames`), made a :class:`Frame` here
        and never checked again."""
        assert reply.image is not None and reply.stamp is not None
        frame = Frame.decoded(reply.image) if mapping is None else mapping.frame(reply.image)
        return Observation.of_frame(
            frame,
            reply.stamp,
            pose=reply.pose,
            collided=reply.collided,
            scan=reply.scan,
            twist=reply.twist,
        )

    # ------------------------------------------------------------------ the Robot protocol
    def hello(self) -> dict[str, Any]:
        """The hello reply's header: protocol version, camera, limits, clock (docs/PROTOCOL.md)."""
        return dict(self._exchange("hello").header)

    def handshake(self) -> Hello:
        """``hello``, validated against the schema; from then on steps are checked against its limits."""
        reply = self._exchange("hello")
        try:
            self.hello_info = parse_hello(reply)
        except BadFrameError as exc:
            self._reject(f"hello: {exc}")
        return self.hello_info

    def reset(self, pose: tuple[float, float, float] | None = None, seed: int | None = None) -> Observation:
        return self._mapped_observation(self._exchange("reset", pose=pose, seed=seed))

    def observe(self) -> Observation:
        return self._mapped_observation(self._exchange("observe"))

    def step(self, v: float, w: float, duration: float) -> Observation:
        return self._mapped_observation(
            self._exchange("step", v=float(v), w=float(w), duration=float(duration))
        )

    def stop(self) -> None:
        self._exchange("stop")
