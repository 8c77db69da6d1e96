"""A repeat run read back from the MCAP that `vtr repeat --mcap` wrote (runtime.mcap_log), for `vtr eval --run`.

Read through runtime.bag_reader (size caps, damage warnings). Every way the file can be wrong is a
BagFileError of one line naming the file (and the topic and message index where one message is at fault):
not an MCAP (a `vtr repeat --log` file, a PNG), a vtr topic carrying another message type, a message that
does not decode, a ``/vtr/step`` message that is not a JSON object, a summary that is not an object or whose
counts are not whole numbers, a command or pose that is not finite. Camera images are counted, not decoded.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime.bag_caps import BagFileError
from vtr.runtime.bag_reader import GuardedBag, shown
from vtr.runtime.mcap_log import TOPICS

_READ = ("/vtr/cmd_vel", "/vtr/pose", "/vtr/image_error", "/vtr/step")
#: Summary fields read as counts, and step fields read as a subgoal index: whole numbers >= 0.
COUNTS = ("subgoals_reached", "steps")


@dataclass
class RecordedRun:
    """A run read back from MCAP: one row per control step (times in seconds from the first step)."""

    times: np.ndarray  # (S,)
    commands: np.ndarray  # (S, 2) v, w
    poses: np.ndarray  # (S, 3), NaN where unknown
    errors: np.ndarray  # (S,), NaN where absent
    steps: list[dict[str, Any]] = field(default_factory=list)  # the JSON channel
    summary: dict[str, Any] | None = None
    image_count: int = 0
    warnings: list[str] = field(default_factory=list)  # damage: the file was read as far as it goes


def _count(value: Any) -> bool:
    """A whole number >= 0 (JSON may spell one 5.0; never a bool, NaN or Infinity)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    if isinstance(value, int):
        return value >= 0
    return math.isfinite(value) and value >= 0 and value.is_integer()


def _step_json(text: str, where: str) -> dict[str, Any]:
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise BagFileError(f"{where} is not JSON ({exc})") from None
    if not isinstance(data, dict):
        raise BagFileError(f"{where} holds a JSON {type(data).__name__}, not an object")
    body = data.get("summary", data)
    if not isinstance(body, dict):
        raise BagFileError(f"{where}: its summary is a JSON {type(body).__name__}, not an object")
    fields = COUNTS if "summary" in data else ("subgoal",)
    for name in fields:
        if name in body and not _count(body[name]):
            raise BagFileError(f"{where}: {name} is {body[name]!r}, not a whole number >= 0")
    if "summary" in data and not isinstance(body.get("status", ""), str | None):
        raise BagFileError(f"{where}: status is {body['status']!r}, not text")
    return data


def _finite(values: tuple[float, ...], where: str) -> tuple[float, ...]:
    if not all(math.isfinite(v) for v in values):
        raise BagFileError(f"{where} holds a value that is not finite: {values}")
    return values


def read_run(path: str | os.PathLike[str]) -> RecordedRun:
    """Read a run written by runtime.mcap_log.McapRunWriter (a .mcap file or a bag folder)."""
    path = Path(path)
    rows: dict[int, dict[str, Any]] = {}
    steps: list[dict[str, Any]] = []
    summary, images = None, 0
    with GuardedBag([path], mcap=True) as bag:
        for conn in bag.connections:
            expected = TOPICS.get(conn.topic)
            if expected is not None and conn.msgtype != expected:
                raise BagFileError(
                    f"{path}: topic {conn.topic} carries {shown(conn.msgtype)}, where a vtr run has {expected}"
                )
        wanted = [c for c in bag.connections if c.topic in _READ or c.topic == "/vtr/camera/image"]
        for conn, i, ns, raw in bag.messages(wanted):
            if conn.topic == "/vtr/camera/image":
                images += 1
                continue
            msg = bag.deserialize(conn, i, raw)
            where = bag.where(conn, i)
            if conn.topic == "/vtr/step":
                data = _step_json(msg.data, where)
                if "summary" in data:
                    summary = data["summary"]
                else:
                    steps.append(data)
                continue
            row = rows.setdefault(ns, {})
            try:
                if conn.topic == "/vtr/cmd_vel":
                    row["cmd"] = _finite((msg.twist.linear.x, msg.twist.angular.z), where)
                elif conn.topic == "/vtr/pose":
                    q = msg.pose.orientation
                    yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
                    row["pose"] = _finite((msg.pose.position.x, msg.pose.position.y, yaw), where)
                else:
                    row["error"] = msg.data
            except AttributeError as exc:  # a damaged schema of the right name: a message without its fields
                raise BagFileError(
                    f"{where}: a {shown(conn.msgtype)} without the fields a vtr run writes ({exc.name} missing)"
                ) from None
        warnings = list(bag.warnings)
    times = sorted(t for t, r in rows.items() if "cmd" in r)
    t0 = times[0] if times else 0
    return RecordedRun(
        times=np.array([(t - t0) * 1e-9 for t in times]),
        commands=np.array([rows[t]["cmd"] for t in times], np.float64).reshape(-1, 2),
        poses=np.array([rows[t].get("pose", (np.nan,) * 3) for t in times], np.float64).reshape(-1, 3),
        errors=np.array([rows[t].get("error", np.nan) for t in times], np.float64),
        steps=steps,
        summary=summary,
        image_count=images,
        warnings=warnings,
    )
