"""The reply half of the wire contract (docs/PROTOCOL.md, "Replies"): encode a server's replies, decode and
validate them on the client. Pure functions over lists of frames; ``runtime.protocol`` re-exports them.

An image reply is a header and one raw ``rgb8`` frame; its header may carry a range ``scan``
(``runtime.scan``), read only when the caller passes the scanner announced in ``hello``, and the robot's
executed ``twist`` (``{"v", "w"}``), read only when ``hello`` announced one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from vtr.runtime.scan import Scan, ScanSpec, scan_from_wire, scan_to_wire
from vtr.runtime.wire_header import (
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
from vtr.runtime.wire_json import (
    MAX_INT,
    BadFrameError,
    ProtocolError,
    integer,
    number,
    pose_field,
    session_field,
    show,
)


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
    scan: Scan | None = None  # the range reading, when the caller passed the announced scanner
    twist: tuple[float, float] | None = None  # (v, w) the robot executed, when the caller expects it


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
    return [header_bytes(header)]


def encode_image_reply(
    cmd: str,
    seq: int,
    session: str,
    stamp: float,
    image: np.ndarray,
    pose: Any = None,
    collided: bool = False,
    scan: Scan | None = None,
    twist: tuple[float, float] | None = None,
) -> list[bytes]:
    """An image reply: header (with the range ``scan`` and the executed ``twist`` (v, w) when given) + one raw
    rgb8 frame."""
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
    if scan is not None:
        header["scan"] = scan_to_wire(scan)
    if twist is not None:
        header["twist"] = {"v": float(twist[0]), "w": float(twist[1])}
    return [header_bytes(header), np.ascontiguousarray(image).tobytes()]


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
    return [header_bytes(header)]


def decode_reply(
    frames: list[bytes],
    expect_cmd: str | None = None,
    expect_seq: int | None = None,
    expect_shape: tuple[int, int] | None = None,
    max_message_bytes: int = MAX_MESSAGE_BYTES,
    expect_scan: ScanSpec | None = None,
    expect_twist: bool = False,
) -> Reply:
    """Parse and validate a reply; raises :class:`BadFrameError` naming the problem.

    ``expect_shape`` is (height, width) of the images the caller can use. ``expect_scan`` is the scanner
    announced in ``hello``: an image reply's ``scan`` (optional, null alike) is then checked against it and
    decoded; without it the field is not read. ``expect_twist`` (hello announced ``twist``) reads an image reply's
    executed ``twist`` (optional, null alike) the same way. An error reply (``ok``
    false) decodes without raising: the caller decides what a refusal means. Its ``seq`` may be null
    (the server could not read the request); otherwise it must equal ``expect_seq`` too.
    """
    err = BadFrameError
    header = parse_header(frames, max_message_bytes, err)
    ok = header.get("ok")
    if not isinstance(ok, bool):
        raise err(f"reply field 'ok' must be true or false, got {show(ok)}")
    cmd, seq = header.get("cmd"), header.get("seq")
    if seq is not None and (type(seq) is not int or abs(seq) > MAX_INT):
        raise err(f"reply field 'seq' must be an integer, got {show(seq)}")
    if cmd is not None and cmd not in COMMANDS:
        raise err(f"reply names unknown command {show(cmd)}")
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
        raise err(f"reply is for command {show(cmd)}, expected {expect_cmd!r}")
    if expect_seq is not None and seq != expect_seq:
        raise err(f"reply has seq {show(seq)}, expected {expect_seq} (stale or out of order)")
    if cmd is None or seq is None:
        raise err("an ok reply must echo the request's 'cmd' and 'seq'")
    session = session_field(header, err, required=True)
    stamp = number(header, "stamp", err)
    if cmd not in IMAGE_COMMANDS:
        if len(frames) != 1:
            raise err(f"{cmd!r} reply must be one frame, got {len(frames)}")
        return Reply(cmd=cmd, seq=seq, ok=True, header=header, stamp=stamp, session=session)
    if header.get("encoding") != ENCODING:
        raise err(f"unsupported image encoding {show(header.get('encoding'))}, expected {ENCODING!r}")
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
        raise err(f"reply field 'collided' must be a bool, got {show(collided)}")
    scan = None
    if expect_scan is not None and header.get("scan") is not None:
        scan = scan_from_wire(header["scan"], expect_scan, err)
    twist = None
    if expect_twist and header.get("twist") is not None:
        twist = twist_from_wire(header["twist"], err)
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
        scan=scan,
        twist=twist,
    )


def twist_from_wire(raw: Any, err: type[BadFrameError] = BadFrameError) -> tuple[float, float]:
    """An image reply's ``twist``: ``{"v": m/s, "w": rad/s}``, finite numbers (docs/PROTOCOL.md)."""
    if not isinstance(raw, dict):
        raise err(f"reply field 'twist' must be an object with 'v' and 'w', got {show(raw)}")
    return number(raw, "v", err, "twist."), number(raw, "w", err, "twist.")
