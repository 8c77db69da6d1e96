"""The wire contract between a robot (or the simulator) and the runtime: pure encode/decode over frames.

The contract for people writing a robot bridge is docs/PROTOCOL.md (every command, field, unit, limit and
reply shape, with examples that tests parse through this module). In short: a message is a list of ZeroMQ
frames; frame 0 is a UTF-8 JSON object (the header), an image reply adds one raw ``rgb8`` frame. Requests:
``hello``, ``reset``, ``observe``, ``step`` (v m/s, w rad/s, duration s), ``stop``. Every reply echoes
``proto``, ``version``, ``cmd`` and ``seq`` and carries ``ok``, ``session`` and ``stamp``. Nothing is ever
pickled. Units and axes follow ROS REP-103.

Decoding is total: whatever the bytes, it returns a value or raises :class:`ProtocolError` (requests) or
:class:`BadFrameError` (replies) with a message a person can act on. Numbers are bounded (integers to
``MAX_INT``, floats finite and within ``MAX_ABS_NUMBER``), JSON nesting to ``MAX_DEPTH``, sizes to
``MAX_HEADER_BYTES``/``MAX_MESSAGE_BYTES``; integer fields take JSON integers only (``1.0`` is refused).
Out-of-range velocities are **rejected**, not clamped: a client that sends |v| > v_max has a bug.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vtr.runtime import contracts as _contracts
from vtr.runtime.request_fast import RequestTemplates
from vtr.runtime.wire_json import (  # noqa: F401  (re-exported)
    MAX_DEPTH,
    MAX_HEADER_BYTES,
    MAX_INT,
    MAX_SESSION_CHARS,
    BadFrameError,
    ProtocolError,
    integer,
    jsonable,
    number,
    parse_json,
    pose_field,
    session_field,
)
from vtr.runtime.wire_json import show as _show

PROTO = "vtr-sim"
VERSION = 1
COMMANDS = ("hello", "reset", "observe", "step", "stop")
IMAGE_COMMANDS = ("reset", "observe", "step")
#: Commands a server refuses when the request names another session (they would move a robot that rebooted).
GUARDED_COMMANDS = ("reset", "step")
ENCODING = "rgb8"

#: Default limits (the paper's robot, from runtime.contracts); one step lasts at most 10 s.
V_MAX = _contracts.V_MAX
W_MAX = _contracts.W_MAX
MAX_DURATION = 10.0
#: Default cap on the total size of one message (a 1024x1024 RGB image fits).
MAX_MESSAGE_BYTES = 4 * 1024 * 1024
#: Largest image side accepted in a reply.
MAX_IMAGE_SIDE = 4096
#: Error codes an error reply may carry in ``code``.
ERROR_CODES = ("bad_request", "session_mismatch", "robot_error")


@dataclass(frozen=True)
class Limits:
    """Bounds a server enforces on ``step`` requests (announced in ``hello``)."""

    v_max: float = V_MAX  # m/s
    w_max: float = W_MAX  # rad/s
    max_duration: float = MAX_DURATION  # s

    def __post_init__(self) -> None:
        for name in ("v_max", "w_max", "max_duration"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"Limits.{name} must be a number, got {value!r}")
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"Limits.{name} must be a positive finite number, got {value!r}")

    def to_dict(self) -> dict[str, float]:
        return {"v_max": self.v_max, "w_max": self.w_max, "max_duration": self.max_duration}


@dataclass(frozen=True)
class Request:
    """A decoded request. ``fields`` holds the command's validated extra fields."""

    cmd: str
    seq: int
    stamp: float | None = None
    fields: dict[str, Any] = field(default_factory=dict)
    #: The server session the client believes it talks to (None: not given).
    session: str | None = None


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
    code: str | None = None
    image: np.ndarray | None = None  # (H, W, 3) uint8, read-only view of the frame
    pose: tuple[float, float, float] | None = None  # (x, y, yaw)
    collided: bool = False


def _parse_header(frames: Any, max_message_bytes: int, err: type[ProtocolError]) -> dict[str, Any]:
    if not isinstance(frames, list | tuple) or not frames:
        raise err("empty message: expected a JSON header frame")
    total = 0
    for frame in frames:  # a plain loop: this runs twice per control step
        if not isinstance(frame, bytes | bytearray | memoryview):
            raise err("every frame must be bytes")
        total += len(frame)
    if total > max_message_bytes:
        raise err(f"message of {total} bytes exceeds the limit of {max_message_bytes} bytes")
    first = frames[0]
    header = parse_json(first if type(first) is bytes else bytes(first), err)
    if not isinstance(header, dict):
        raise err(f"header must be a JSON object, got {type(header).__name__}")
    if header.get("proto") != PROTO:
        raise err(f"wrong protocol {_show(header.get('proto'))}, expected {PROTO!r}")
    version = header.get("version")
    if type(version) is not int or version != VERSION:
        raise err(
            f"unsupported protocol version {_show(version)}, this side speaks version {VERSION} (an integer)"
        )
    return header


def pose_dict(pose: Any) -> dict[str, float] | None:
    """A pose as the wire's ``{"x", "y", "yaw"}``; accepts a tuple or any object with x/y/yaw attributes."""
    if pose is None:
        return None
    if isinstance(pose, tuple | list | np.ndarray):
        x, y, yaw = (float(v) for v in pose)
    else:
        x, y, yaw = float(pose.x), float(pose.y), float(pose.yaw)
    return {"x": x, "y": y, "yaw": yaw}


def _header_bytes(header: dict[str, Any]) -> bytes:
    # allow_nan=False: a NaN must never reach the wire as the non-standard token `NaN`.
    return json.dumps(header, separators=(",", ":"), allow_nan=False).encode("utf-8")


# --------------------------------------------------------------------------------------------- requests

_TEMPLATES = RequestTemplates(PROTO, VERSION, MAX_SESSION_CHARS)


def encode_request(
    cmd: str, seq: int, stamp: float | None = None, limits: Limits | None = None, **fields: Any
) -> list[bytes]:
    """Build a request; refuses (ProtocolError) what a server with ``limits`` would refuse.

    ``limits`` None checks the shape of the fields only (the server checks the ranges it announced).
    ``session`` (a field) names the server session the request is meant for.
    """
    if cmd not in COMMANDS:
        raise ProtocolError(f"unknown command {cmd!r}; known: {', '.join(COMMANDS)}")
    fast = _TEMPLATES.header(cmd, seq, stamp, limits, fields)
    if fast is not None:  # what decode_request accepts, checked on the values (no JSON round trip)
        return [fast]
    return encode_request_checked(cmd, seq, stamp, limits, fields)


def encode_request_checked(
    cmd: str, seq: int, stamp: float | None, limits: Limits | None, fields: dict[str, Any]
) -> list[bytes]:
    """The general path of :func:`encode_request`: ``json.dumps``, then ``decode_request`` of the result."""
    header: dict[str, Any] = {"proto": PROTO, "version": VERSION, "cmd": cmd, "seq": int(seq)}
    if stamp is not None:
        header["stamp"] = stamp
    for key, value in fields.items():
        if value is not None:
            header[key] = pose_dict(value) if key == "pose" else value
    try:
        frames = [_header_bytes(header)]
    except (TypeError, ValueError) as exc:
        raise ProtocolError(f"cannot encode {cmd!r} request: {exc}") from None
    decode_request(frames, limits)  # refuse to send what the server would refuse
    return frames


def decode_request(
    frames: list[bytes], limits: Limits | None = Limits(), max_message_bytes: int = MAX_MESSAGE_BYTES
) -> Request:
    """Parse and validate a request; raises :class:`ProtocolError` naming the problem.

    ``limits`` None skips the velocity/duration range checks (a client that has not read ``hello``).
    """
    header = _parse_header(frames, max_message_bytes, ProtocolError)
    if len(frames) != 1:
        raise ProtocolError(f"a request is one header frame, got {len(frames)} frames")
    cmd = header.get("cmd")
    if cmd not in COMMANDS:
        raise ProtocolError(f"unknown command {_show(cmd)}; known: {', '.join(COMMANDS)}")
    seq = integer(header, "seq")
    if seq < 0:
        raise ProtocolError(f"field 'seq' must be >= 0, got {seq}")
    stamp = number(header, "stamp") if header.get("stamp") is not None else None
    session = session_field(header, ProtocolError, required=False)
    fields: dict[str, Any] = {}
    if cmd == "reset":
        if header.get("pose") is not None:
            fields["pose"] = pose_field(header["pose"], ProtocolError)
        if header.get("seed") is not None:
            seed = integer(header, "seed")
            if seed < 0:
                raise ProtocolError(f"field 'seed' must be >= 0, got {seed}")
            fields["seed"] = seed
    elif cmd == "step":
        v, w, duration = number(header, "v"), number(header, "w"), number(header, "duration")
        if duration <= 0:
            raise ProtocolError(f"duration={duration} s is out of range: must be > 0")
        if limits is not None:
            if abs(v) > limits.v_max:
                raise ProtocolError(f"v={v} m/s is out of range: |v| must be <= v_max={limits.v_max} m/s")
            if abs(w) > limits.w_max:
                raise ProtocolError(f"w={w} rad/s is out of range: |w| must be <= w_max={limits.w_max} rad/s")
            if duration > limits.max_duration:
                raise ProtocolError(
                    f"duration={duration} s is out of range: must be in (0, {limits.max_duration}] s"
                )
        fields.update(v=v, w=w, duration=duration)
    return Request(cmd=cmd, seq=seq, stamp=stamp, fields=fields, session=session)


def peek_cmd_seq(frames: Any) -> tuple[str | None, int | None]:
    """Best-effort (cmd, seq) of a request that failed to decode, to echo them in the error reply."""
    try:
        header = parse_json(bytes(frames[0]))
        cmd, seq = header.get("cmd"), header.get("seq")
    except Exception:
        return None, None
    return (
        cmd if cmd in COMMANDS else None,
        seq if type(seq) is int and 0 <= seq <= MAX_INT else None,
    )


# --------------------------------------------------------------------------------------------- replies


def _reply_header(
    cmd: str | None, seq: int | None, session: str | None, stamp: float | None
) -> dict[str, Any]:
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


def encode_error(
    error: str,
    cmd: Any = None,
    seq: Any = None,
    session: str | None = None,
    stamp: float | None = None,
    code: str = "bad_request",
) -> list[bytes]:
    """An error reply. cmd/seq are echoed only when they were readable and of the right type."""
    header = _reply_header(
        cmd if isinstance(cmd, str) and cmd in COMMANDS else None,
        seq if type(seq) is int and 0 <= seq <= MAX_INT else None,
        session,
        stamp if isinstance(stamp, float | int) and math.isfinite(stamp) else None,
    )
    header.update(ok=False, error=str(error)[:2000], code=code if code in ERROR_CODES else "bad_request")
    return [_header_bytes(header)]


def decode_reply(
    frames: list[bytes],
    expect_cmd: str | None = None,
    expect_seq: int | None = None,
    expect_shape: tuple[int, int] | None = None,
    max_message_bytes: int = MAX_MESSAGE_BYTES,
) -> Reply:
    """Parse and validate a reply; raises :class:`BadFrameError` naming the problem.

    ``expect_shape`` is (height, width) of the images the caller can use. An error reply (``ok``
    false) decodes without raising: the caller decides what a refusal means. Its ``seq`` may be null
    (the server could not read the request); otherwise it must equal ``expect_seq`` too.
    """
    err = BadFrameError
    header = _parse_header(frames, max_message_bytes, err)
    ok = header.get("ok")
    if not isinstance(ok, bool):
        raise err(f"reply field 'ok' must be true or false, got {_show(ok)}")
    cmd, seq = header.get("cmd"), header.get("seq")
    if seq is not None and (type(seq) is not int or abs(seq) > MAX_INT):
        raise err(f"reply field 'seq' must be an integer, got {_show(seq)}")
    if cmd is not None and cmd not in COMMANDS:
        raise err(f"reply names unknown command {_show(cmd)}")
    if not ok:
        error, code = header.get("error"), header.get("code")
        if len(frames) != 1 or not isinstance(error, str):
            raise err("error reply must be one header frame with a string 'error'")
        if expect_seq is not None and seq is not None and seq != expect_seq:
            raise err(f"error reply has seq {seq}, expected {expect_seq} (stale or out of order)")
        stamp = number(header, "stamp", err) if header.get("stamp") is not None else None
        return Reply(
            cmd=cmd,
            seq=seq,
            ok=False,
            header=header,
            stamp=stamp,
            session=session_field(header, err, required=False),
            error=error[:2000],
            code=code if isinstance(code, str) else None,
        )
    if expect_cmd is not None and cmd != expect_cmd:
        raise err(f"reply is for command {_show(cmd)}, expected {expect_cmd!r}")
    if expect_seq is not None and seq != expect_seq:
        raise err(f"reply has seq {_show(seq)}, expected {expect_seq} (stale or out of order)")
    if cmd is None or seq is None:
        raise err("an ok reply must echo the request's 'cmd' and 'seq'")
    session = session_field(header, err, required=True)
    stamp = number(header, "stamp", err)
    if cmd not in IMAGE_COMMANDS:
        if len(frames) != 1:
            raise err(f"{cmd!r} reply must be one frame, got {len(frames)}")
        return Reply(cmd=cmd, seq=seq, ok=True, header=header, stamp=stamp, session=session)
    if header.get("encoding") != ENCODING:
        raise err(f"unsupported image encoding {_show(header.get('encoding'))}, expected {ENCODING!r}")
    height, width = integer(header, "height", err), integer(header, "width", err)
    if not (0 < height <= MAX_IMAGE_SIDE and 0 < width <= MAX_IMAGE_SIDE):
        raise err(f"image size {height}x{width} is out of range (1..{MAX_IMAGE_SIDE})")
    if expect_shape is not None and (height, width) != tuple(expect_shape):
        raise err(f"image is {height}x{width}, expected {expect_shape[0]}x{expect_shape[1]}")
    if len(frames) != 2:
        raise err(f"image reply must have 2 frames (header, pixels), got {len(frames)}")
    payload, expected = frames[1], height * width * 3
    if len(payload) != expected:
        kind = "truncated" if len(payload) < expected else "oversized"
        raise err(f"{kind} pixel frame: {len(payload)} bytes, expected {height}*{width}*3={expected}")
    image = np.frombuffer(payload, dtype=np.uint8).reshape(height, width, 3)
    pose = None if header.get("pose") is None else pose_field(header["pose"], err)
    collided = header.get("collided", False)
    if not isinstance(collided, bool):
        raise err(f"reply field 'collided' must be a bool, got {_show(collided)}")
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
