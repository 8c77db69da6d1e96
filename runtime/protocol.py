"""The wire contract between a robot (or the simulator) and the runtime: pure encode/decode over frames.

The contract for people writing a robot bridge is docs/PROTOCOL.md (every command, field, unit, limit and
reply shape, with examples that tests parse through this module). In short: a message is a list of ZeroMQ
frames; frame 0 is a UTF-8 JSON object (the header), an image reply adds one raw ``rgb8`` frame and may
carry a range ``scan`` in its header (``runtime.scan``). Requests:
``hello``, ``reset``, ``observe``, ``step`` (v m/s, w rad/s, duration s), ``stop``. Every reply echoes
``proto``, ``version``, ``cmd`` and ``seq`` and carries ``ok``, ``session`` and ``stamp``. Nothing is ever
pickled. Units and axes follow ROS REP-103.

Decoding is total: whatever the bytes, it returns a value or raises :class:`ProtocolError` (requests) or
:class:`BadFrameError` (replies) with a message a person can act on. Numbers are bounded (integers to
``MAX_INT``, floats finite and within ``MAX_ABS_NUMBER``), JSON nesting to ``MAX_DEPTH``, sizes to
``MAX_HEADER_BYTES``/``MAX_MESSAGE_BYTES``; integer fields take JSON integers only (``1.0`` is refused).
Out-of-range velocities are **rejected**, not clamped: a client that sends |v| > v_max has a bug.

This module holds the request codec and is the one name to import: the header every message shares lives
in ``runtime.wire_header``, the reply codec in ``runtime.reply_codec``, both re-exported here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from vtr.runtime import contracts as _contracts
from vtr.runtime.reply_codec import (  # noqa: F401  (re-exported)
    Reply,
    decode_reply,
    encode_error,
    encode_image_reply,
    encode_ok,
)
from vtr.runtime.request_fast import RequestTemplates
from vtr.runtime.wire_header import (  # noqa: F401  (re-exported)
    COMMANDS,
    ENCODING,
    ERROR_CODES,
    IMAGE_COMMANDS,
    MAX_IMAGE_SIDE,
    MAX_MESSAGE_BYTES,
    PROTO,
    VERSION,
    header_bytes,
    parse_header,
    pose_dict,
)
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

#: Commands a server refuses when the request names another session (they would move a robot that rebooted).
GUARDED_COMMANDS = ("reset", "step")

#: Default limits (the paper's robot, from runtime.contracts); one step lasts at most 10 s.
V_MAX = _contracts.V_MAX
W_MAX = _contracts.W_MAX
MAX_DURATION = 10.0


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
        frames = [header_bytes(header)]
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
    header = parse_header(frames, max_message_bytes, ProtocolError)
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
