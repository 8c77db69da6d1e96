"""Serve an in-process simulator over ZeroMQ with the wire contract of ``runtime.protocol``.

One REP socket, one simulator. Two clocks (``ServerConfig.mode``):

- ``"lockstep"`` (default): simulated time advances only inside ``step`` requests, so a run is
  deterministic whatever the client's speed; ``stop`` only records the zero twist.
- ``"realtime"``: simulated time follows the wall clock (times ``realtime_factor``). The last twist keeps
  driving the robot between requests until ``stop``, and a ``step`` reply is sent once ``duration``
  has passed. This is how a real robot behaves, and what makes the daemon's continuous mode (no zero
  command while the next command is computed) differ from stop-and-go.
 Every request gets exactly one reply; a bad request
gets ``{"ok": false, "error": ...}`` naming the problem and the server keeps serving. The loop polls
with a timeout and checks a stop flag, so SIGINT/SIGTERM shut it down cleanly.

Only this module (and ``local_robot.py``) couples sim2d to the runtime; the simulator core never
imports ZeroMQ.
"""

from __future__ import annotations

import math
import multiprocessing
import signal
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import zmq

from vtr.runtime import protocol
from vtr.runtime.protocol import Limits, ProtocolError


class _Pose(NamedTuple):
    """Fallback pose type when sim2d.Pose is unavailable (a fake simulator in tests)."""

    x: float
    y: float
    yaw: float


def make_pose(x: float, y: float, yaw: float) -> Any:
    """A ``sim2d.Pose`` when the simulator core is importable, else an equivalent named tuple."""
    try:
        from vtr.sim2d import Pose  # type: ignore[attr-defined]
    except ImportError:
        return _Pose(x, y, yaw)
    return Pose(x, y, yaw)


@dataclass
class ServerConfig:
    """How the simulator server listens and what it accepts."""

    #: ZeroMQ endpoint to bind; ``tcp://127.0.0.1:*`` picks a free port (see ``SimServer.endpoint``).
    bind: str = "tcp://127.0.0.1:5555"
    #: sim2d.SimConfig for the simulator ``serve`` builds; None means SimConfig() defaults.
    sim: Any = None
    #: Requests larger than this (all frames together) get an error reply.
    max_message_bytes: int = protocol.MAX_MESSAGE_BYTES
    #: Hard cap handed to ZeroMQ (ZMQ_MAXMSGSIZE): a peer sending more is disconnected without a reply.
    hard_max_message_bytes: int = 64 * 1024 * 1024
    #: Linear speed limit in m/s; faster step requests are rejected (the paper's robot: 0.5).
    v_max: float = protocol.V_MAX
    #: Angular speed limit in rad/s (the paper's robot: 1.0).
    w_max: float = protocol.W_MAX
    #: Longest simulated duration one step request may ask for, in seconds.
    max_step_duration: float = protocol.MAX_DURATION
    #: How often the loop wakes up to check for shutdown, in milliseconds.
    poll_ms: int = 100
    #: "lockstep": time advances only in step requests; "realtime": time follows the wall clock.
    mode: str = "lockstep"
    #: "realtime" only: simulated seconds per wall-clock second.
    realtime_factor: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.bind, str) or "://" not in self.bind:
            raise ValueError(f"bind must be a ZeroMQ endpoint like tcp://127.0.0.1:5555, got {self.bind!r}")
        if self.max_message_bytes < 1024:
            raise ValueError(f"max_message_bytes must be >= 1024, got {self.max_message_bytes}")
        if self.hard_max_message_bytes < self.max_message_bytes:
            raise ValueError(
                f"hard_max_message_bytes={self.hard_max_message_bytes} must be >= "
                f"max_message_bytes={self.max_message_bytes}"
            )
        for name in ("v_max", "w_max", "max_step_duration"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        if self.poll_ms < 1:
            raise ValueError(f"poll_ms must be >= 1, got {self.poll_ms}")
        if self.mode not in ("lockstep", "realtime"):
            raise ValueError(f"mode must be 'lockstep' or 'realtime', got {self.mode!r}")
        if not (math.isfinite(self.realtime_factor) and self.realtime_factor > 0):
            raise ValueError(f"realtime_factor must be a positive number, got {self.realtime_factor!r}")

    @property
    def limits(self) -> Limits:
        return Limits(v_max=self.v_max, w_max=self.w_max, max_duration=self.max_step_duration)


@dataclass
class Deferred:
    """A realtime ``step`` whose reply is due once the wall clock reaches ``deadline``."""

    deadline: float
    req: protocol.Request


class SimServer:
    """Request handling (frames in, frames out) plus a socket loop around it.

    ``clock`` (monotonic seconds) is injectable so that realtime mode can be tested without sleeping.
    """

    def __init__(
        self, simulator: Any, cfg: ServerConfig | None = None, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.sim = simulator
        self.cfg = cfg or ServerConfig()
        self.clock = clock
        self._wall = clock()  # realtime: wall-clock instant the simulator has been advanced to
        #: Changes at every server start, so a client can tell a restarted server from a stale reply.
        self.session = uuid.uuid4().hex[:12]
        self.requests = 0
        self.errors = 0
        #: The last twist commanded (v, w); stop sets it to zero. In lockstep it matters only for the record.
        self.twist = (0.0, 0.0)
        #: Command of the last well-formed request (for logs and tests).
        self.last_cmd: str | None = None
        self.endpoint: str | None = None
        self._stop = threading.Event()
        self._ready = threading.Event()

    # ------------------------------------------------------------------ request handling
    @property
    def realtime(self) -> bool:
        return self.cfg.mode == "realtime"

    def catch_up(self, now: float | None = None) -> None:
        """Realtime: drive the simulator with the current twist up to wall-clock instant ``now``."""
        now = self.clock() if now is None else now
        remaining = (now - self._wall) * self.cfg.realtime_factor
        self._wall = max(self._wall, now)
        advance = getattr(self.sim, "advance", None)  # no render when the simulator offers it
        while remaining > 1e-9:
            chunk = min(remaining, self.cfg.max_step_duration)
            if advance is not None:
                advance(self.twist[0], self.twist[1], chunk)
            else:
                self.sim.step(self.twist[0], self.twist[1], chunk)
            remaining -= chunk

    def handle(self, frames: list[bytes]) -> list[bytes]:
        """One request -> one reply (a realtime step is answered at once, after waiting). Never raises."""
        result = self.handle_deferred(frames)
        if isinstance(result, Deferred):
            wait = result.deadline - self.clock()
            if wait > 0:
                time.sleep(wait)
            return self.finish(result)
        return result

    def finish(self, deferred: Deferred) -> list[bytes]:
        """The reply of a realtime step, once its deadline has passed."""
        try:
            self.catch_up(max(deferred.deadline, self.clock()))
            return self._image_reply(deferred.req, self.sim.observe())
        except Exception as exc:
            self.errors += 1
            req = deferred.req
            return protocol.encode_error(
                f"simulator error on {req.cmd!r}: {exc}", req.cmd, req.seq, self.session
            )

    def handle_deferred(self, frames: list[bytes]) -> list[bytes] | Deferred:
        """Like :meth:`handle`, but a realtime step returns a :class:`Deferred` instead of waiting."""
        self.requests += 1
        try:
            req = protocol.decode_request(frames, self.cfg.limits, self.cfg.max_message_bytes)
        except ProtocolError as exc:
            self.errors += 1
            cmd, seq = protocol.peek_cmd_seq(frames)
            return protocol.encode_error(str(exc), cmd, seq, self.session)
        self.last_cmd = req.cmd
        try:
            if self.realtime:
                self.catch_up()
                if req.cmd == "step":
                    self.twist = (req.fields["v"], req.fields["w"])
                    return Deferred(self._wall + req.fields["duration"] / self.cfg.realtime_factor, req)
            return self._dispatch(req)
        except Exception as exc:  # a simulator failure must not kill the server
            self.errors += 1
            return protocol.encode_error(
                f"simulator error on {req.cmd!r}: {exc}", req.cmd, req.seq, self.session
            )

    def _image_reply(self, req: protocol.Request, image: Any) -> list[bytes]:
        return protocol.encode_image_reply(
            req.cmd,
            req.seq,
            self.session,
            float(self.sim.time),
            image,
            self.sim.pose,
            bool(self.sim.collided),
        )

    def _dispatch(self, req: protocol.Request) -> list[bytes]:
        sim = self.sim
        if req.cmd == "hello":
            info = protocol.jsonable(sim.info())
            return protocol.encode_ok(
                "hello",
                req.seq,
                self.session,
                float(sim.time),
                protocol_version=protocol.VERSION,
                camera=info.get("camera") if isinstance(info, dict) else None,
                limits=self.cfg.limits.to_dict(),
                time=float(sim.time),
                mode=self.cfg.mode,
                info=info,
            )
        if req.cmd == "reset":
            pose = req.fields.get("pose")
            image = sim.reset(pose=None if pose is None else make_pose(*pose), seed=req.fields.get("seed"))
            self.twist = (0.0, 0.0)
            self._wall = self.clock()
            return self._image_reply(req, image)
        if req.cmd == "observe":
            return self._image_reply(req, sim.observe())
        if req.cmd == "step":
            v, w, duration = req.fields["v"], req.fields["w"], req.fields["duration"]
            self.twist = (v, w)
            image = sim.step(v, w, duration)
            return self._image_reply(req, image)
        # stop: from now on the robot stands still (realtime); in lockstep no time runs between requests.
        self.twist = (0.0, 0.0)
        return protocol.encode_ok("stop", req.seq, self.session, float(sim.time))

    # ------------------------------------------------------------------ socket loop
    def stop(self) -> None:
        """Ask the loop to exit at its next poll."""
        self._stop.set()

    def wait_ready(self, timeout: float = 10.0) -> str:
        """Block until the socket is bound; returns the bound endpoint (with the real port)."""
        if not self._ready.wait(timeout):
            raise TimeoutError(f"server did not bind {self.cfg.bind} within {timeout} s")
        assert self.endpoint is not None
        return self.endpoint

    def serve_forever(self) -> None:
        """Bind, answer requests until :meth:`stop`, then close the socket."""
        ctx = zmq.Context()
        sock = ctx.socket(zmq.REP)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.MAXMSGSIZE, self.cfg.hard_max_message_bytes)
        try:
            sock.bind(self.cfg.bind)
            self.endpoint = sock.getsockopt_string(zmq.LAST_ENDPOINT)
            self._ready.set()
            poller = zmq.Poller()
            poller.register(sock, zmq.POLLIN)
            pending: Deferred | None = None
            while not self._stop.is_set():
                if pending is not None:  # realtime step: wait for its deadline, still watching the flag
                    wait = pending.deadline - self.clock()
                    if wait > 0:
                        time.sleep(min(wait, self.cfg.poll_ms / 1000))
                        continue
                    sock.send_multipart(self.finish(pending))
                    pending = None
                    continue
                if not poller.poll(self.cfg.poll_ms):
                    if self.realtime:
                        self.catch_up()
                    continue
                result = self.handle_deferred(sock.recv_multipart())
                if isinstance(result, Deferred):
                    pending = result
                else:
                    sock.send_multipart(result)
        finally:
            sock.close(linger=0)
            ctx.term()


def serve(cfg: ServerConfig, simulator: Any = None) -> int:
    """`vtr sim serve`: build the simulator (unless given), serve until SIGINT/SIGTERM, return 0."""
    if simulator is None:
        from vtr.sim2d import SimConfig, Simulator  # type: ignore[attr-defined]  # pymunk lives behind this

        simulator = Simulator(cfg.sim if cfg.sim is not None else SimConfig())
        simulator.reset()
    server = SimServer(simulator, cfg)
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, lambda *_: server.stop())
    try:
        thread = threading.Thread(target=_announce, args=(server,), daemon=True)
        thread.start()
        server.serve_forever()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    print(f"vtr sim serve: stopped after {server.requests} requests ({server.errors} refused)", flush=True)
    return 0


def _announce(server: SimServer) -> None:
    try:
        endpoint = server.wait_ready()
    except TimeoutError:
        return
    print(f"vtr sim serve: listening on {endpoint} (session {server.session}, {server.cfg.mode})", flush=True)


# ---------------------------------------------------------------------------------------- background runs


class ServerThread:
    """Run a SimServer in a daemon thread (tests, notebooks). Use as a context manager."""

    def __init__(self, simulator: Any, cfg: ServerConfig | None = None) -> None:
        self.server = SimServer(simulator, cfg or ServerConfig(bind="tcp://127.0.0.1:*"))
        self._thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def start(self, timeout: float = 10.0) -> ServerThread:
        self._thread.start()
        self.server.wait_ready(timeout)
        return self

    @property
    def endpoint(self) -> str:
        assert self.server.endpoint is not None
        return self.server.endpoint

    def stop(self, timeout: float = 5.0) -> None:
        self.server.stop()
        self._thread.join(timeout)

    def __enter__(self) -> ServerThread:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _process_main(cfg: ServerConfig, factory: Callable[[], Any] | None, conn: Any) -> None:
    simulator = factory() if factory is not None else None
    if simulator is None:
        from vtr.sim2d import SimConfig, Simulator  # type: ignore[attr-defined]

        simulator = Simulator(cfg.sim if cfg.sim is not None else SimConfig())
        simulator.reset()
    server = SimServer(simulator, cfg)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: server.stop())
    threading.Thread(target=lambda: conn.send(server.wait_ready()), daemon=True).start()
    server.serve_forever()


@dataclass
class ServerProcess:
    """A server running in a child process; ``endpoint`` is where it listens."""

    process: Any
    endpoint: str
    _closed: bool = field(default=False, repr=False)

    def terminate(self, timeout: float = 5.0) -> int | None:
        """SIGTERM (clean shutdown), then SIGKILL if it does not exit; returns the exit code."""
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(timeout)
        return self.process.exitcode

    def kill(self, timeout: float = 5.0) -> int | None:
        """SIGKILL: the server dies without closing anything (a crash)."""
        if self.process.is_alive():
            self.process.kill()
            self.process.join(timeout)
        return self.process.exitcode

    def __enter__(self) -> ServerProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.terminate()


def start_server_process(
    cfg: ServerConfig, simulator_factory: Callable[[], Any] | None = None, timeout: float = 30.0
) -> ServerProcess:
    """Start a server in a fresh (spawned) process and wait until it listens.

    ``simulator_factory`` must be picklable (a module-level function); None builds
    ``sim2d.Simulator(cfg.sim)``. ``cfg.bind`` may use port ``*``: the real endpoint is returned.
    """
    ctx = multiprocessing.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    process = ctx.Process(target=_process_main, args=(cfg, simulator_factory, child), daemon=True)
    process.start()
    child.close()
    deadline = time.monotonic() + timeout
    while not parent.poll(0.1):
        if not process.is_alive() or time.monotonic() > deadline:
            process.kill()
            process.join(1.0)
            raise RuntimeError(f"simulator server did not start on {cfg.bind} (exit code {process.exitcode})")
    return ServerProcess(process=process, endpoint=parent.recv())
