"""A robot bridge in one file, written from the protocol's documentation alone: numpy + pyzmq, no vtr imports.

The "robot" lives in a 4 m x 4 m room whose four walls have different colours and stripes; its camera renders
128x128 rgb8 by casting one ray per image column. Replace ``World`` with your robot's camera and motors, keep
``serve``, and `vtr check-robot` tells you what is left to fix.

    python examples/minimal_robot_server.py --bind tcp://127.0.0.1:5555 [--noise 0.05]
    vtr check-robot tcp://127.0.0.1:5555

``--noise`` makes the motors imperfect as in our simulator (sim2d's SimConfig.noise): per reset, a speed-scale,
turn-scale and curvature error (a miscalibrated robot), then per step a proportional and an additive jitter.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import uuid

import numpy as np
import zmq

PROTO, VERSION = "vtr-sim", 1
COMMANDS = ("hello", "reset", "observe", "step", "stop")
LIMITS = {"v_max": 0.5, "w_max": 1.0, "max_duration": 10.0}
CAMERA = {"width": 128, "height": 128, "fov_deg": 90.0, "height_m": 0.3}
HALF, RADIUS = 2.0, 0.2  # half the room's side and the robot's radius, metres
WALL_COLOURS = np.array([[200, 60, 50], [60, 160, 70], [50, 90, 200], [220, 190, 60]], np.float64)


class World:
    """A unicycle in a square room (lockstep: time passes only inside ``step``)."""

    def __init__(self, noise: float = 0.0) -> None:
        self.noise = noise
        self.reset()

    def reset(self, x: float = 0.0, y: float = 0.0, yaw: float = 0.0, seed: int = 0) -> None:
        self.x, self.y, self.yaw, self.time, self.collided = x, y, yaw, 0.0, False
        self.rng = np.random.default_rng(seed)  # same seed, same motor errors: runs are reproducible
        b = self.noise * self.rng.standard_normal(3)
        self.bias = (1 + b[0], 1 + b[1], 0.5 * b[2])  # v scale, w scale, curvature drift (rad per metre)

    def step(self, v: float, w: float, duration: float) -> None:
        if self.noise:  # what the motors execute: the episode's bias, then this step's jitter
            e = self.noise * self.rng.standard_normal(4)
            v, w = v * self.bias[0], w * self.bias[1] + self.bias[2] * v
            v = float(v * (1 + e[0]) + 0.1 * LIMITS["v_max"] * e[1] * (v != 0))  # plain floats for JSON
            w = float(w * (1 + e[2]) + 0.1 * LIMITS["w_max"] * e[3] * (w != 0))
        for _ in range(max(1, math.ceil(duration / 0.02))):  # integrate in 20 ms substeps
            dt = duration / max(1, math.ceil(duration / 0.02))
            x, y = self.x + v * dt * math.cos(self.yaw), self.y + v * dt * math.sin(self.yaw)
            self.collided = max(abs(x), abs(y)) > HALF - RADIUS  # the bumper stops the robot at the wall
            if not self.collided:
                self.x, self.y = x, y
            self.yaw = (self.yaw + w * dt + math.pi) % (2 * math.pi) - math.pi
        self.time += duration

    def render(self) -> np.ndarray:
        w, h = CAMERA["width"], CAMERA["height"]
        fov = math.radians(CAMERA["fov_deg"])
        angles = self.yaw + fov * (0.5 - (np.arange(w) + 0.5) / w)  # left to right
        dx, dy = np.cos(angles), np.sin(angles)
        with np.errstate(divide="ignore"):  # distance to the x walls and to the y walls along each ray
            tx = np.where(dx > 0, (HALF - self.x) / dx, (-HALF - self.x) / dx)
            ty = np.where(dy > 0, (HALF - self.y) / dy, (-HALF - self.y) / dy)
        dist = np.minimum(tx, ty)
        wall = np.where(tx < ty, np.where(dx > 0, 0, 1), np.where(dy > 0, 2, 3))
        along = np.where(tx < ty, self.y + dist * dy, self.x + dist * dx)  # where the ray hits the wall
        colour = WALL_COLOURS[wall] * (0.75 + 0.25 * (np.floor(along * 4) % 2))[:, None]
        wall_half = np.clip(
            h * 0.6 / (dist * np.cos(angles - self.yaw)), 0, h / 2
        )  # pixels above the horizon
        rows = np.abs(np.arange(h) - h / 2 + 0.5)[:, None]  # pixels from the horizon
        background = np.where(
            np.arange(h)[:, None, None] < h / 2, [230, 230, 240], [120, 100, 80]
        )  # ceiling, floor
        return np.where((rows < wall_half)[..., None], colour[None], background).astype(np.uint8)


def _reject(token: str) -> float:
    raise ValueError(f"non-finite number {token}")


class Refused(ValueError):
    """A request this robot will not execute; ``code`` goes into the error reply."""

    def __init__(self, message: str, code: str = "bad_request") -> None:
        super().__init__(message)
        self.code = code


def handle(world: World, session: str, frames: list[bytes]) -> list[bytes]:
    """One request -> one reply. Every reply echoes proto, version, cmd and seq, and carries session and stamp."""
    reply = {"proto": PROTO, "version": VERSION, "cmd": None, "seq": None, "ok": True, "session": session}
    try:
        req = json.loads(frames[0], parse_constant=_reject)
        if not isinstance(req, dict):
            raise ValueError("the header must be a JSON object")
        cmd, seq = req.get("cmd"), req.get("seq")
        reply.update(cmd=cmd if cmd in COMMANDS else None, seq=seq if type(seq) is int else None)
        if req.get("proto") != PROTO or req.get("version") != VERSION:
            raise ValueError(f"expected proto {PROTO!r} version {VERSION}")
        if type(seq) is not int or len(frames) != 1:
            raise ValueError("a request is one JSON frame with an integer 'seq'")
        if (
            cmd in ("reset", "step") and req.get("session", session) != session
        ):  # meant for us before a reboot
            raise Refused(f"session {req['session']!r} is not this robot's {session!r}", "session_mismatch")
        if cmd == "hello":
            reply.update(protocol_version=VERSION, camera=CAMERA, limits=LIMITS, dt=0.1, mode="lockstep")
        elif cmd == "reset":
            pose, seed = req.get("pose") or {}, req.get("seed", 0)
            if type(seed) is not int or seed < 0:
                raise ValueError("seed must be an integer >= 0")
            world.reset(
                *(float(pose.get(k, 0.0)) for k in ("x", "y", "yaw")), seed=seed
            )  # default: the centre
        elif cmd == "step":
            v, w, duration = (req.get(k) for k in ("v", "w", "duration"))
            if not all(type(a) in (int, float) for a in (v, w, duration)):
                raise ValueError("step needs numbers v (m/s), w (rad/s) and duration (s)")
            if abs(v) > LIMITS["v_max"] or abs(w) > LIMITS["w_max"]:
                raise ValueError(f"|v| <= {LIMITS['v_max']} m/s and |w| <= {LIMITS['w_max']} rad/s")
            if not 0 < duration <= LIMITS["max_duration"]:
                raise ValueError(f"duration must be in (0, {LIMITS['max_duration']}] s")
            world.step(v, w, duration)
        elif cmd not in COMMANDS:
            raise ValueError(f"unknown command {cmd!r}; known: {', '.join(COMMANDS)}")
    except (ValueError, TypeError, AttributeError) as exc:  # json errors are ValueErrors
        reply.update(ok=False, error=str(exc), code=getattr(exc, "code", "bad_request"), stamp=world.time)
        return [json.dumps(reply).encode()]
    reply["stamp"] = world.time
    if reply["cmd"] in ("hello", "stop"):
        return [json.dumps(reply).encode()]
    image = world.render()
    pose = {"x": world.x, "y": world.y, "yaw": world.yaw}
    reply.update(
        encoding="rgb8", height=image.shape[0], width=image.shape[1], pose=pose, collided=world.collided
    )
    return [json.dumps(reply).encode(), image.tobytes()]


def serve(bind: str, noise: float = 0.0) -> None:
    sock = zmq.Context.instance().socket(zmq.REP)
    try:
        sock.bind(bind)
    except zmq.ZMQError as exc:  # a port in use, an address not of this machine: one line, exit 2
        sock.close(linger=0)
        print(
            f"minimal_robot_server.py: cannot bind --bind {bind}: {zmq.strerror(exc.errno)}", file=sys.stderr
        )
        raise SystemExit(2) from None
    world, session = World(noise), uuid.uuid4().hex[:12]
    print(f"minimal robot server on {sock.getsockopt_string(zmq.LAST_ENDPOINT)}", flush=True)
    while True:
        sock.send_multipart(handle(world, session, sock.recv_multipart()))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bind", default="tcp://127.0.0.1:5555", help="ZeroMQ endpoint to bind")
    parser.add_argument(
        "--noise", type=float, default=0.0, help="actuation noise level, 0 = off (default: 0)"
    )
    args = parser.parse_args()
    if not 0 <= args.noise <= 1:
        parser.error(f"--noise must be in [0, 1], got {args.noise}")
    try:
        serve(args.bind, args.noise)
    except KeyboardInterrupt:
        pass
