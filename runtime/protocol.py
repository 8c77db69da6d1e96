"""The wire contract between a robot (or the simulator) and the runtime: pure encode/decode over frames.

A message is a list of ZeroMQ frames (``bytes``). Frame 0 is a small UTF-8 JSON object, the header::

    {"proto": "vtr-sim", "version": 1, "cmd": "step", "seq": 7, "stamp": 12.3, ...}

Requests (client -> server) and their extra header fields:

========  ==================================================  ==========================================
command   request fields                                      ok reply
========  ==================================================  ==========================================
hello     none                                                protocol_version, session, camera, limits,
                                                              time, info (the simulator's ``info()``)
reset     pose: {"x","y","yaw"} (optional), seed: int >= 0    image reply
          (optional)
observe   none                                                image reply (no time advance)
step      v (m/s), w (rad/s), duration (s)                    image reply after applying (v, w) for
                                                              ``duration`` of simulated time
stop      none                                                {"ok": true} (zero velocity)
========  ==================================================  ==========================================

Every reply carries ``"ok"``, ``"session"`` (a token that changes whenever the server restarts) and
``"stamp"`` (the server's clock: simulated seconds). An *image reply* adds ``"encoding": "rgb8"``,
``"height"``, ``"width"``, ``"pose"`` ({"x","y","yaw"} or null when the robot does not know it) and
``"collided"`` (bool), followed by exactly one frame of ``height * width * 3`` raw bytes, row-major HWC RGB.
An error reply is ``{"ok": false, "error": "<what was wrong>"}`` plus whatever of cmd/seq could be read.
Nothing is ever pickled.

Units and axes follow ROS REP-103: v is Twist linear.x, w is angular.z (counter-clockwise positive).

Out-of-range velocities are **rejected**, not clamped: a client that sends |v| > v_max has a bug (a
model that was exported with other limits, a unit mix-up), and silently clamping would hide it. The
error message names the limit. Durations must lie in (0, max_duration].

Every malformed message raises :class:`ProtocolError` with a message a person can act on: malformed
JSON, wrong proto/version, unknown command, missing, non-finite or out-of-range fields, oversized or
truncated frames, wrong encoding or shape. Decoding a *reply* raises :class:`BadFrameError` (a
subclass) so that a client can count the frames it had to reject.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vtr.runtime import contracts as _contracts

PROTO = "vtr-sim"
VERSION = 1
COMMANDS = ("hello", "reset", "observe", "step", "stop")
IMAGE_COMMANDS = ("reset", "observe", "step")
ENCODING = "rgb8"

#: Default limits (the paper's robot, from runtime.contracts); one step lasts at most 10 s.
V_MAX = _contracts.V_MAX
W_MAX = _contracts.W_MAX
MAX_DURATION = 10.0
#: A header larger than this is refused before parsing.
MAX_HEADER_BYTES = 64 * 1024
#: Default cap on the total size of one message (a 1024x1024 RGB image fits).
MAX_MESSAGE_BYTES = 4 * 1024 * 1024
#: Largest image side accepted in a reply.
MAX_IMAGE_SIDE = 4096


class ProtocolError(ValueError):
    """A message that does not follow this protocol; the message says what is wrong."""


class BadFrameError(ProtocolError):
    """A reply the client must reject (counted by the client, never fed to the network)."""


@dataclass(frozen=True)
class Limits:
    """Bounds a server enforces on ``step`` requests."""

    v_max: float = V_MAX  # m/s
    w_max: float = W_MAX  # rad/s
    max_duration: float = MAX_DURATION  # s

    def __post_init__(self) -> None:
        for name in ("v_max", "w_max", "max_duration"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"Limits.{name} must be a positive finite number, got {value!r}")

    def to_dict(self) -> dict[str, float]:
        return {"v_max": self.v_max, "w_max": self.w_max, "max_duration": self.max_duration}


@dataclass(frozen=True)
class Request:
    """A decoded request. ``fields`` holds the command's validated extra fields."""

    cmd: str
    seq: int
    stamp: float
    fields: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Reply:
    """A decoded reply. ``image`` is set for image replies; ``header`` is the whole JSON header."""

    cmd: str | None
    seq: int | None
    ok: bool
    header: dict[str, Any]
    stamp: float | None = None
    session: str | None = None
    error: str | None = None
    image: np.ndarray | None = None  # (H, W, 3) uint8, read-only view of the frame
    pose: tuple[float, float, float] | None = None  # (x, y, yaw)
    collided: bool = False


# --------------------------------------------------------------------------------------------- helpers


def _header_bytes(header: dict[str, Any]) -> bytes:
    # allow_nan=False: a NaN must never reach the wire as the non-standard token `NaN`.
    return json.dumps(header, separators=(",", ":"), allow_nan=False).encode("utf-8")


def _parse_header(frames: list[bytes], max_message_bytes: int, err: type[ProtocolError]) -> dict[str, Any]:
    if not isinstance(frames, list | tuple) or not frames:
        raise err("empty message: expected a JSON header frame")
    total = sum(len(f) for f in frames)
    if total > max_message_bytes:
        raise err(f"message of {total} bytes exceeds the limit of {max_message_bytes} bytes")
    raw = bytes(frames[0])
    if len(raw) > MAX_HEADER_BYTES:
        raise err(f"header frame of {len(raw)} bytes exceeds the limit of {MAX_HEADER_BYTES} bytes")
    try:
        header = json.loads(raw.decode("utf-8"), parse_constant=_reject_constant)
    except (UnicodeDecodeError, json.JSONDecodeError, ValueError) as exc:
        raise err(f"malformed JSON header: {exc}") from None
    if not isinstance(header, dict):
        raise err(f"header must be a JSON object, got {type(header).__name__}")
    if header.get("proto") != PROTO:
        raise err(f"wrong protocol {header.get('proto')!r}, expected {PROTO!r}")
    version = header.get("version")
    if version != VERSION or isinstance(version, bool):
        raise err(f"unsupported protocol version {version!r}, this side speaks version {VERSION}")
    return header


def _reject_constant(token: str) -> float:
    raise ValueError(f"non-finite number {token} in JSON")


def _number(header: dict[str, Any], key: str, err: type[ProtocolError], *, where: str = "") -> float:
    if key not in header:
        raise err(f"missing field {where}{key!r}")
    value = header[key]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise err(f"field {where}{key!r} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise err(f"field {where}{key!r} must be finite, got {value!r}")
    return float(value)


def _integer(header: dict[str, Any], key: str, err: type[ProtocolError]) -> int:
    if key not in header:
        raise err(f"missing field {key!r}")
    value = header[key]
    if isinstance(value, bool) or not isinstance(value, int):
        raise err(f"field {key!r} must be an integer, got {value!r}")
    return value


def _pose(value: Any, err: type[ProtocolError], key: str = "pose") -> tuple[float, float, float]:
    if not isinstance(value, dict):
        raise err(f"field {key!r} must be an object {{'x', 'y', 'yaw'}}, got {value!r}")
    return tuple(_number(value, k, err, where=f"{key}.") for k in ("x", "y", "yaw"))  # type: ignore[return-value]


def pose_dict(pose: Any) -> dict[str, float] | None:
    """A pose as the wire's ``{"x", "y", "yaw"}``; accepts a tuple or any object with x/y/yaw attributes."""
    if pose is None:
        return None
    if isinstance(pose, tuple | list | np.ndarray):
        x, y, yaw = (float(v) for v in pose)
    else:
        x, y, yaw = float(pose.x), float(pose.y), float(pose.yaw)
    return {"x": x, "y": y, "yaw": yaw}


def jsonable(value: Any) -> Any:
    """The simulator's info() as plain JSON (dataclasses/tuples/numpy scalars flattened, NaN -> None)."""

    def default(obj: Any) -> Any:
        if hasattr(obj, "__dataclass_fields__"):
            return {k: getattr(obj, k) for k in obj.__dataclass_fields__}
        if hasattr(obj, "tolist"):
            return obj.tolist()
        return str(obj)

    def clean(obj: Any) -> Any:
        if isinstance(obj, float) and not math.isfinite(obj):
            return None
        if isinstance(obj, dict):
            return {str(k): clean(v) for k, v in obj.items()}
        if isinstance(obj, list):
            return [clean(v) for v in obj]
        return obj

    return clean(json.loads(json.dumps(value, default=default)))


# --------------------------------------------------------------------------------------------- requests


def encode_request(cmd: str, seq: int, stamp: float = 0.0, **fields: Any) -> list[bytes]:
    """Build a request. Fields are validated by :func:`decode_request` on the other side, and here too."""
    if cmd not in COMMANDS:
        raise ProtocolError(f"unknown command {cmd!r}; known: {', '.join(COMMANDS)}")
    header: dict[str, Any] = {"proto": PROTO, "version": VERSION, "cmd": cmd, "seq": int(seq), "stamp": stamp}
    for key, value in fields.items():
        if value is None:
            continue
        header[key] = pose_dict(value) if key == "pose" else value
    try:
        frames = [_header_bytes(header)]
    except ValueError as exc:
        raise ProtocolError(f"cannot encode {cmd!r} request: {exc}") from None
    decode_request(frames)  # refuse to send what the server would refuse
    return frames


def decode_request(
    frames: list[bytes], limits: Limits = Limits(), max_message_bytes: int = MAX_MESSAGE_BYTES
) -> Request:
    """Parse and validate a request; raises :class:`ProtocolError` naming the problem."""
    header = _parse_header(frames, max_message_bytes, ProtocolError)
    if len(frames) != 1:
        raise ProtocolError(f"a request is one header frame, got {len(frames)} frames")
    cmd = header.get("cmd")
    if cmd not in COMMANDS:
        raise ProtocolError(f"unknown command {cmd!r}; known: {', '.join(COMMANDS)}")
    seq = _integer(header, "seq", ProtocolError)
    stamp = _number(header, "stamp", ProtocolError)
    fields: dict[str, Any] = {}
    if cmd == "reset":
        if header.get("pose") is not None:
            fields["pose"] = _pose(header["pose"], ProtocolError)
        if header.get("seed") is not None:
            seed = _integer(header, "seed", ProtocolError)
            if seed < 0:
                raise ProtocolError(f"field 'seed' must be >= 0, got {seed}")
            fields["seed"] = seed
    elif cmd == "step":
        v = _number(header, "v", ProtocolError)
        w = _number(header, "w", ProtocolError)
        duration = _number(header, "duration", ProtocolError)
        if abs(v) > limits.v_max:
            raise ProtocolError(f"v={v} m/s is out of range: |v| must be <= v_max={limits.v_max} m/s")
        if abs(w) > limits.w_max:
            raise ProtocolError(f"w={w} rad/s is out of range: |w| must be <= w_max={limits.w_max} rad/s")
        if not 0 < duration <= limits.max_duration:
            raise ProtocolError(
                f"duration={duration} s is out of range: must be in (0, {limits.max_duration}] s"
            )
        fields.update(v=v, w=w, duration=duration)
    return Request(cmd=cmd, seq=seq, stamp=stamp, fields=fields)


# --------------------------------------------------------------------------------------------- replies


def _reply_header(cmd: str | None, seq: int | None, session: str, stamp: float | None) -> dict[str, Any]:
    return {
        "proto": PROTO,
        "version": VERSION,
        "cmd": cmd,
        "seq": seq,
        "ok": True,
        "session": session,
        "stamp": stamp,
    }


def encode_ok(cmd: str, seq: int, session: str, stamp: float, **fields: Any) -> list[bytes]:
    """A reply without an image (hello, stop)."""
    header = _reply_header(cmd, seq, session, stamp)
    header.update(fields)
    return [_header_bytes(header)]


def encode_image_reply(
    cmd: str,
    seq: int,
    session: str,
    stamp: float,
    image: np.ndarray,
    pose: Any = None,
    collided: bool = False,
) -> list[bytes]:
    """An image reply: header + one raw rgb8 frame."""
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ProtocolError(f"image must be (H, W, 3) uint8, got {image.shape} {image.dtype}")
    header = _reply_header(cmd, seq, session, stamp)
    header.update(
        encoding=ENCODING,
        height=int(image.shape[0]),
        width=int(image.shape[1]),
        pose=pose_dict(pose),
        collided=bool(collided),
    )
    return [_header_bytes(header), np.ascontiguousarray(image).tobytes()]


def encode_error(error: str, cmd: Any = None, seq: Any = None, session: str | None = None) -> list[bytes]:
    """An error reply. cmd/seq are echoed only when they were readable and of the right type."""
    header = {
        "proto": PROTO,
        "version": VERSION,
        "cmd": cmd if isinstance(cmd, str) and cmd in COMMANDS else None,
        "seq": seq if isinstance(seq, int) and not isinstance(seq, bool) else None,
        "ok": False,
        "session": session,
        "error": str(error),
    }
    return [_header_bytes(header)]


def peek_cmd_seq(frames: list[bytes]) -> tuple[Any, Any]:
    """Best-effort (cmd, seq) of a request that failed to decode, to echo them in the error reply."""
    try:
        header = json.loads(bytes(frames[0])[:MAX_HEADER_BYTES].decode("utf-8"))
        return header.get("cmd"), header.get("seq")
    except Exception:
        return None, None


def decode_reply(
    frames: list[bytes],
    expect_cmd: str | None = None,
    expect_seq: int | None = None,
    expect_shape: tuple[int, int] | None = None,
    max_message_bytes: int = MAX_MESSAGE_BYTES,
) -> Reply:
    """Parse and validate a reply; raises :class:`BadFrameError` naming the problem.

    ``expect_shape`` is (height, width) of the images the caller can use. An error reply (``ok``
    false) decodes without raising: the caller decides what a refusal means.
    """
    header = _parse_header(frames, max_message_bytes, BadFrameError)
    ok = header.get("ok")
    if not isinstance(ok, bool):
        raise BadFrameError(f"reply field 'ok' must be true or false, got {ok!r}")
    cmd, seq = header.get("cmd"), header.get("seq")
    session = header.get("session")
    if session is not None and not isinstance(session, str):
        raise BadFrameError(f"reply field 'session' must be a string, got {session!r}")
    if not ok:
        error = header.get("error")
        if len(frames) != 1 or not isinstance(error, str):
            raise BadFrameError("error reply must be one header frame with a string 'error'")
        return Reply(cmd=cmd, seq=seq, ok=False, header=header, session=session, error=error)
    if expect_cmd is not None and cmd != expect_cmd:
        raise BadFrameError(f"reply is for command {cmd!r}, expected {expect_cmd!r}")
    if expect_seq is not None and seq != expect_seq:
        raise BadFrameError(f"reply has seq {seq!r}, expected {expect_seq} (stale or out of order)")
    if cmd not in COMMANDS:
        raise BadFrameError(f"reply names unknown command {cmd!r}")
    stamp = _number(header, "stamp", BadFrameError)
    if cmd not in IMAGE_COMMANDS:
        if len(frames) != 1:
            raise BadFrameError(f"{cmd!r} reply must be one frame, got {len(frames)}")
        return Reply(cmd=cmd, seq=seq, ok=True, header=header, stamp=stamp, session=session)
    if header.get("encoding") != ENCODING:
        raise BadFrameError(f"unsupported image encoding {header.get('encoding')!r}, expected {ENCODING!r}")
    height = _integer(header, "height", BadFrameError)
    width = _integer(header, "width", BadFrameError)
    if not (0 < height <= MAX_IMAGE_SIDE and 0 < width <= MAX_IMAGE_SIDE):
        raise BadFrameError(f"image size {height}x{width} is out of range (1..{MAX_IMAGE_SIDE})")
    if expect_shape is not None and (height, width) != tuple(expect_shape):
        raise BadFrameError(f"image is {height}x{width}, expected {expect_shape[0]}x{expect_shape[1]}")
    if len(frames) != 2:
        raise BadFrameError(f"image reply must have 2 frames (header, pixels), got {len(frames)}")
    payload = frames[1]
    expected = height * width * 3
    if len(payload) != expected:
        kind = "truncated" if len(payload) < expected else "oversized"
        raise BadFrameError(
            f"{kind} pixel frame: {len(payload)} bytes, expected {height}*{width}*3={expected}"
        )
    image = np.frombuffer(payload, dtype=np.uint8).reshape(height, width, 3)
    pose = None if header.get("pose") is None else _pose(header["pose"], BadFrameError)
    collided = header.get("collided", False)
    if not isinstance(collided, bool):
        raise BadFrameError(f"reply field 'collided' must be a bool, got {collided!r}")
    return Reply(
        cmd=cmd,
        seq=seq,
        ok=True,
        header=header,
        stamp=stamp,
        session=session,
        image=image,
        pose=pose,
        collided=collided,
    )
