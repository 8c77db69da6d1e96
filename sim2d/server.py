"""Serve an in-process simulator over ZeroMQ with the wire contract of ``runtime.protocol``.

One REP socket, one simulator. Two clocks (``ServerConfig.mode``):

- ``"lockstep"`` (default): simulated time advances only inside ``step`` requests, so a run is
  deterministic whatever the client's speed; ``stop`` only records the zero twist.
- ``"realtime"``: simulated time follows the wall clock (times ``realtime_factor``). The last twist keeps
  driving the robot between requests until ``stop``, and a ``step`` reply is sent once ``duration``
  has passed. A watchdog (``cmd_vel_timeout``, 0.5 s by default, 0 disables; the idea of ros2_controllers'
  diff_drive_controller) brings the robot to zero when no new step arrived within
  ``max(duration, cmd_vel_timeout)`` of the last one, so a client killed mid-route leaves a robot at rest.

Every request gets exactly one reply; a bad request, a request for another session (a step meant for the
robot before a restart) or any exception while handling one gets an error reply naming the problem, and
the server keeps serving. The loop polls with a timeout and checks a stop flag, so SIGINT/SIGTERM shut it
down cleanly. ``hello`` announces the camera, limits and clock (docs/PROTOCOL.md); it names the map, never
its path on this machine. With ``ServerConfig.scan`` (the default) it also announces the simulator's range
scanner (sim2d.rangefinder), and every image reply carries a scan taken with the image. With ``ServerConfig.twist``
(the default) image replies report the executed twist (the one driving the robot: the last step's, zero after a
stop or the watchdog). With ``ServerConfig.drive_script`` the robot drives a ROUTE.json by itself, as its own
joystick would (sim2d/joystick.py: how `vtr teach --follow` is tried without a second person).

Only this module (and ``local_robot.py``) couples sim2d to the runtime; the simulator core never
imports ZeroMQ.
"""

from __future__ import annotations

import logging
import math
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import zmq

from vtr.runtime import protocol
from vtr.runtime.protocol import ProtocolError
from vtr.sim2d.joystick import ScriptedDriver
from vtr.sim2d.server_config import ServerConfig

log = logging.getLogger(__name__)


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
class Deferred:
    """A realtime ``step`` whose reply is due once the wall clock reaches ``deadline``."""

    deadline: float
    req: protocol.Request


class BindError(OSError):
    """The server could not bind its endpoint: the port is taken, or the interface does not exist."""


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
        self._contact = False  # realtime: a contact while advancing, not yet reported
        #: Changes at every server start, so a client can tell a restarted server from a stale reply.
        self.session = uuid.uuid4().hex[:12]
        self.requests = 0
        self.errors = 0
        #: The last twist commanded (v, w); stop sets it to zero. In lockstep it matters only for the record.
        self.twist = (0.0, 0.0)
        #: Realtime: wall-clock instant at which the watchdog zeroes the twist (None: not armed).
        self.twist_deadline: float | None = None
        #: Realtime: times the watchdog stopped the robot.
        self.watchdog_stops = 0
        #: Command of the last well-formed request (for logs and tests).
        self.last_cmd: str | None = None
        self.endpoint: str | None = None
        #: The range scanner announced in hello and read for every image (None: camera only, or a simulator
        #: without one).
        rangefinder = getattr(simulator, "rangefinder", None) if self.cfg.scan else None
        self.scan_spec = None if rangefinder is None else rangefinder.spec
        #: Requests served, by command (a test asks whether a follower sent any motion command).
        self.served: dict[str, int] = {}
        #: The robot's own joystick (a drive script), None: only clients move it.
        self.driver = None if self.cfg.drive_script is None else ScriptedDriver(self.cfg.drive_script)
        if self.driver is not None:
            self.sim.reset(pose=make_pose(*self.cfg.drive_script.start))
        self._stop = threading.Event()
        self._ready = threading.Event()

    # ------------------------------------------------------------------ request handling
    @property
    def realtime(self) -> bool:
        return self.cfg.mode == "realtime"

    def catch_up(self, now: float | None = None) -> None:
        """Realtime: drive the simulator with the current twist up to wall-clock instant ``now``; the
        watchdog zeroes the twist at ``twist_deadline``."""
        now = self.clock() if now is None else now
        if self.driver is not None:
            return self._drive_until(now)
        while self._wall < now:
            until = now
            if self.twist_deadline is not None and self.twist_deadline < now:
                until = max(self._wall, self.twist_deadline)
            self._advance((until - self._wall) * self.cfg.realtime_factor)
            self._wall = until
            if until < now or (self.twist_deadline is not None and self.twist_deadline <= now):
                if self.twist != (0.0, 0.0):
                    self.watchdog_stops += 1
                self.twist, self.twist_deadline = (0.0, 0.0), None

    def _drive_until(self, now: float) -> None:
        """Realtime with a drive script: the joystick's twist, piece by piece up to each change."""
        rate = self.cfg.realtime_factor
        while self._wall < now:
            v, w, change = self.driver.twist(float(self.sim.time))
            until = (
                now if math.isinf(change) else min(now, self._wall + max(change - self.sim.time, 1e-6) / rate)
            )
            self.twist = (v, w)
            self._advance((until - self._wall) * rate)
            self._wall = until
        self.twist = self.driver.twist(float(self.sim.time))[:2]
        if not self.driver.holding(float(self.sim.time)):
            self.driver = (
                None  # the script is over: an ordinary robot from now on (a reset restarts its clock)
            )

    def _advance(self, remaining: float) -> None:
        advance = getattr(self.sim, "advance", None)  # no render when the simulator offers it
        while remaining > 1e-9:
            chunk = min(remaining, self.cfg.max_step_duration)
            if advance is not None:
                advance(self.twist[0], self.twist[1], chunk)
            else:
                self.sim.step(self.twist[0], self.twist[1], chunk)
            # a contact in any chunk is reported with the next image: the simulator's flag is the last chunk's
            self._contact = self._contact or bool(self.sim.collided)
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
            req = deferred.req
            return self._error(f"simulator error on {req.cmd!r}: {exc}", req.cmd, req.seq, "robot_error")

    def _stamp(self) -> float | None:
        try:
            stamp = float(self.sim.time)
        except Exception:
            return None
        return stamp if math.isfinite(stamp) else None

    def _error(self, message: str, cmd: object, seq: object, code: str = "bad_request") -> list[bytes]:
        self.errors += 1
        return protocol.encode_error(message, cmd, seq, self.session, self._stamp(), code)

    def handle_deferred(self, frames: list[bytes]) -> list[bytes] | Deferred:
        """Like :meth:`handle`, but a realtime step returns a :class:`Deferred` instead of waiting."""
        self.requests += 1
        try:
            return self._handle(frames)
        except Exception as exc:  # whatever went wrong with this request, the server answers and serves on
            log.warning("request %d failed: %s: %s", self.requests, type(exc).__name__, exc)
            cmd, seq = protocol.peek_cmd_seq(frames)
            return self._error(f"server error: {type(exc).__name__}: {exc}", cmd, seq, "robot_error")

    def _handle(self, frames: list[bytes]) -> list[bytes] | Deferred:
        try:
            req = protocol.decode_request(frames, self.cfg.limits, self.cfg.max_message_bytes)
        except ProtocolError as exc:
            log.debug("refused request %d: %s", self.requests, exc)
            cmd, seq = protocol.peek_cmd_seq(frames)
            return self._error(str(exc), cmd, seq)
        self.last_cmd = req.cmd
        self.served[req.cmd] = self.served.get(req.cmd, 0) + 1
        if self.driver is not None and req.cmd in ("step", "reset"):
            self.catch_up()
            if self.driver is not None and self.driver.holding(float(self.sim.time)):
                return self._error(
                    "the robot is driven by its own joystick (a drive script); it takes no motion command "
                    "until the script ends",
                    req.cmd,
                    req.seq,
                    "robot_error",
                )
        if req.session is not None and req.session != self.session and req.cmd in protocol.GUARDED_COMMANDS:
            return self._error(
                f"session mismatch: this is session {self.session}, the request was for {req.session} "
                "(the robot restarted); not executed",
                req.cmd,
                req.seq,
                "session_mismatch",
            )
        try:
            if self.realtime:
                self.catch_up()
                if req.cmd == "step":
                    self.twist = (req.fields["v"], req.fields["w"])
                    duration = req.fields["duration"] / self.cfg.realtime_factor
                    if self.cfg.cmd_vel_timeout > 0:
                        self.twist_deadline = self._wall + max(duration, self.cfg.cmd_vel_timeout)
                    return Deferred(self._wall + duration, req)
            return self._dispatch(req)
        except Exception as exc:  # a simulator failure must not kill the server
            return self._error(f"simulator error on {req.cmd!r}: {exc}", req.cmd, req.seq, "robot_error")

    def _image_reply(self, req: protocol.Request, image: Any) -> list[bytes]:
        collided, self._contact = bool(self.sim.collided) or self._contact, False
        scan = self.sim.scan() if self.scan_spec is not None else None
        twist = self.twist if self.cfg.twist else None
        return protocol.encode_image_reply(
            req.cmd, req.seq, self.session, float(self.sim.time), image, self.sim.pose, collided, scan, twist
        )

    def _dispatch(self, req: protocol.Request) -> list[bytes]:
        sim = self.sim
        if req.cmd == "hello":
            return protocol.encode_ok("hello", req.seq, self.session, float(sim.time), **self.announce())
        if req.cmd == "reset":
            pose = req.fields.get("pose")
            image = sim.reset(pose=None if pose is None else make_pose(*pose), seed=req.fields.get("seed"))
            self.twist, self.twist_deadline, self._contact = (0.0, 0.0), None, False
            self._wall = self.clock()
            return self._image_reply(req, image)
        if req.cmd == "observe":
            if self.driver is not None:  # the follower's first look starts the joystick
                self.driver.start(float(sim.time))
                self.twist = self.driver.twist(float(sim.time))[:2]
            return self._image_reply(req, sim.observe())
        if req.cmd == "step":
            v, w, duration = req.fields["v"], req.fields["w"], req.fields["duration"]
            self.twist = (v, w)
            image = sim.step(v, w, duration)
            return self._image_reply(req, image)
        # stop: from now on the robot stands still (realtime); in lockstep no time runs between requests.
        self.twist, self.twist_deadline = (0.0, 0.0), None
        return protocol.encode_ok("stop", req.seq, self.session, float(sim.time))

    def announce(self) -> dict[str, object]:
        """The hello fields (docs/PROTOCOL.md): camera, limits, clock; the map's name, never its path."""
        info = protocol.jsonable(self.sim.info())
        info = info if isinstance(info, dict) else {}
        info.pop("map_source", None)
        cam = info.get("camera") if isinstance(info.get("camera"), dict) else {}
        camera = {k: cam.get(k) for k in ("width", "height", "fov_deg")}
        camera["height_m"] = cam.get("height_m", cam.get("camera_height"))
        fields: dict[str, object] = {
            "protocol_version": protocol.VERSION,
            "robot": "vtr-sim2d",
            "map": info.get("map") if isinstance(info.get("map"), str) else None,
            "camera": camera,
            "limits": self.cfg.limits.to_dict(),
            "dt": float(info.get("physics_dt") or 0.02),
            "mode": self.cfg.mode,
            "realtime_factor": self.cfg.realtime_factor,
            "cmd_vel_timeout": self.cfg.cmd_vel_timeout if self.realtime else 0.0,
            "time": float(self.sim.time),
            "info": info,
        }
        if self.scan_spec is not None:
            fields["scan"] = self.scan_spec.to_dict()
        if self.cfg.twist:  # the twist driving the robot: the last step's command (or the drive script's)
            fields["twist"] = {"source": "commanded"}
        return fields

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

    def _serve_once(self, sock: zmq.Socket, poller: zmq.Poller, pending: Deferred | None) -> Deferred | None:
        """One turn of the loop: finish a due realtime step, or wait for and answer one request."""
        if pending is not None:  # realtime step: wait for its deadline, still watching the flag
            wait = pending.deadline - self.clock()
            if wait > 0:
                time.sleep(min(wait, self.cfg.poll_ms / 1000))
                return pending
            sock.send_multipart(self.finish(pending))
            return None
        timeout_ms = self.cfg.poll_ms
        if self.realtime and self.twist_deadline is not None:  # wake up when the watchdog is due
            timeout_ms = max(1, min(timeout_ms, int((self.twist_deadline - self.clock()) * 1000) + 1))
        if not poller.poll(timeout_ms):
            if self.realtime:
                self.catch_up()
            return None
        result = self.handle_deferred(sock.recv_multipart())
        if isinstance(result, Deferred):
            return result
        sock.send_multipart(result)
        return None

    def serve_forever(self) -> None:
        """Bind, answer requests until :meth:`stop`, then close the socket."""
        ctx = zmq.Context()
        sock = ctx.socket(zmq.REP)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.MAXMSGSIZE, self.cfg.hard_max_message_bytes)
        try:
            try:
                sock.bind(self.cfg.bind)
            except zmq.ZMQError as exc:  # callers need not know ZeroMQ to report a taken port
                raise BindError(f"cannot bind {self.cfg.bind}: {exc}") from None
            self.endpoint = sock.getsockopt_string(zmq.LAST_ENDPOINT)
            self._ready.set()
            poller = zmq.Poller()
            poller.register(sock, zmq.POLLIN)
            pending: Deferred | None = None
            while not self._stop.is_set():
                try:
                    pending = self._serve_once(sock, poller, pending)
                except zmq.ZMQError as exc:  # a failed send/recv loses one message, never the server
                    log.warning("socket error, serving on: %s", exc)
                    pending = None
        finally:
            sock.close(linger=0)
            ctx.term()


# Background runs (threads, child processes) and `vtr sim serve`'s loop live in server_launch; their names stay
# importable from here.
from vtr.sim2d.server_launch import ServerProcess, ServerThread, serve, start_server_process  # noqa: E402

__all__ = [
    "Deferred",
    "ServerConfig",
    "ServerProcess",
    "ServerThread",
    "SimServer",
    "serve",
    "start_server_process",
]
