"""What every message of the protocol shares, requests and replies alike: the protocol's name, version,
commands and size limits, and the header frame read and written under them (docs/PROTOCOL.md, "Messages").

``runtime.protocol`` re-exports all of it; the request codec lives there, the reply codec in
``runtime.reply_codec``.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from vtr.runtime.wire_json import ProtocolError, parse_json, show

PROTO = "vtr-sim"
VERSION = 1
COMMANDS = ("hello", "reset", "observe", "step", "stop")
IMAGE_COMMANDS = ("reset", "observe", "step")
ENCODING = "rgb8"
#: Default cap on the total size of one message (a 1024x1024 RGB image fits).
MAX_MESSAGE_BYTES = 4 * 1024 * 1024
#: Largest image side accepted in a reply.
MAX_IMAGE_SIDE = 4096
#: Error codes an error reply may carry in ``code``.
ERROR_CODES = ("bad_request", "session_mismatch", "robot_error")


def parse_header(frames: Any, max_message_bytes: int, err: type[ProtocolError]) -> dict[str, Any]:
    """Frame 0 of a message as a JSON object of this protocol and version; ``err`` for anything else."""
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
        raise err(f"wrong protocol {show(header.get('proto'))}, expected {PROTO!r}")
    version = header.get("version")
    if type(version) is not int or version != VERSION:
        raise err(
            f"unsupported protocol version {show(version)}, this side speaks version {VERSION} (an integer)"
        )
    return header


def header_bytes(header: dict[str, Any]) -> bytes:
    # allow_nan=False: a NaN must never reach the wire as the non-standard token `NaN`.
    return json.dumps(header, separators=(",", ":"), allow_nan=False).encode("utf-8")


def pose_dict(pose: Any) -> dict[str, float] | None:
    """A pose as the wire's ``{"x", "y", "yaw"}``; accepts a tuple or any object with x/y/yaw attributes."""
    if pose is None:
        return None
    if isinstance(pose, tuple | list | np.ndarray):
        x, y, yaw = (float(v) for v in pose)
    else:
        x, y, yaw = float(pose.x), float(pose.y), float(pose.yaw)
    return {"x": x, "y": y, "yaw": yaw}
