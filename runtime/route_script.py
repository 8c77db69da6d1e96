"""ROUTE.json: a scripted drive for `vtr teach`.

``{"name": str (optional), "start": {"x": m, "y": m, "yaw": rad}, "segments": [{"v": m/s, "w": rad/s,
"duration": s}, ...]}``. Velocities must respect the robot's limits (|v| <= 0.5, |w| <= 1.0 by default);
out-of-range values are rejected, like on the wire.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from typing import Any

from vtr.runtime import protocol


class RouteScriptError(ValueError):
    """A malformed ROUTE.json; the message names the field."""


@dataclass(frozen=True)
class Segment:
    v: float  # m/s
    w: float  # rad/s
    duration: float  # s


@dataclass(frozen=True)
class RouteScript:
    start: tuple[float, float, float]  # (x, y, yaw)
    segments: tuple[Segment, ...]
    name: str = "route"

    @property
    def duration(self) -> float:
        return sum(s.duration for s in self.segments)

    def commands(self, dt: float) -> list[tuple[float, float, float]]:
        """The script as (v, w, duration) steps no longer than dt: each segment split into equal steps."""
        out = []
        for s in self.segments:
            n = max(1, math.ceil(s.duration / dt - 1e-9))
            out.extend([(s.v, s.w, s.duration / n)] * n)
        return out


def _num(obj: dict[str, Any], key: str, where: str) -> float:
    if key not in obj:
        raise RouteScriptError(f"{where}.{key}: missing {key!r}")
    value = obj[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise RouteScriptError(f"{where}.{key} must be a finite number, got {value!r}")
    return float(value)


def parse_route_script(
    data: Any, v_max: float = protocol.V_MAX, w_max: float = protocol.W_MAX
) -> RouteScript:
    """Validate a decoded ROUTE.json object."""
    if not isinstance(data, dict):
        raise RouteScriptError(f"route script must be a JSON object, got {type(data).__name__}")
    start = data.get("start")
    if not isinstance(start, dict):
        raise RouteScriptError("route script needs 'start': {'x', 'y', 'yaw'}")
    pose = (_num(start, "x", "start"), _num(start, "y", "start"), _num(start, "yaw", "start"))
    raw = data.get("segments")
    if not isinstance(raw, list) or not raw:
        raise RouteScriptError("route script needs a non-empty list 'segments'")
    segments = []
    for i, seg in enumerate(raw):
        where = f"segments[{i}]"
        if not isinstance(seg, dict):
            raise RouteScriptError(f"{where} must be an object {{'v', 'w', 'duration'}}")
        v, w, d = _num(seg, "v", where), _num(seg, "w", where), _num(seg, "duration", where)
        if abs(v) > v_max:
            raise RouteScriptError(f"{where}.v={v} exceeds the limits: |v| <= v_max={v_max} m/s")
        if abs(w) > w_max:
            raise RouteScriptError(f"{where}.w={w} exceeds the limits: |w| <= w_max={w_max} rad/s")
        if d <= 0:
            raise RouteScriptError(f"{where}.duration must be > 0 s, got {d}")
        segments.append(Segment(v, w, d))
    name = data.get("name", "route")
    if not isinstance(name, str):
        raise RouteScriptError(f"'name' must be a string, got {name!r}")
    return RouteScript(start=pose, segments=tuple(segments), name=name)


def load_route_script(path: str | os.PathLike[str]) -> RouteScript:
    """Read and validate a ROUTE.json file."""
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except json.JSONDecodeError as exc:
        raise RouteScriptError(f"{path}: not valid JSON: {exc}") from None
    except UnicodeDecodeError:
        raise RouteScriptError(f"{path}: not a ROUTE.json file (not UTF-8 text)") from None
    try:
        script = parse_route_script(data)
    except RouteScriptError as exc:
        raise RouteScriptError(f"{path}: {exc}") from None
    if script.name == "route":
        script = RouteScript(script.start, script.segments, os.path.splitext(os.path.basename(path))[0])
    return script
