"""Scripted routes: a start pose and a list of constant (v, w) segments (format in docs/ARCHITECTURE.md)."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

from sim2d.config import V_MAX, W_MAX, Pose

ROUTES_DIR = Path(__file__).resolve().parent / "routes"


@dataclass(frozen=True)
class Segment:
    v: float  # m/s
    w: float  # rad/s
    duration: float  # s


@dataclass(frozen=True)
class Route:
    name: str
    start: Pose
    segments: tuple[Segment, ...]

    @property
    def duration(self) -> float:
        return sum(s.duration for s in self.segments)

    def commands(self, dt: float) -> list[tuple[float, float, float]]:
        """The route as (v, w, duration) steps no longer than dt (the last step of a segment may be shorter)."""
        out = []
        for s in self.segments:
            n = max(1, math.ceil(s.duration / dt - 1e-9))
            full = s.duration / n
            out.extend([(s.v, s.w, full)] * n)
        return out


def list_routes() -> list[str]:
    """Names of the routes shipped in sim2d/routes."""
    return sorted(p.stem for p in ROUTES_DIR.glob("*.json"))


def _num(obj: dict, key: str, where: str) -> float:
    value = obj.get(key) if isinstance(obj, dict) else None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where}.{key}: expected a finite number, got {value!r}")
    return float(value)


def load_route(name_or_path: str | os.PathLike[str]) -> Route:
    """Load a route by name (sim2d/routes/NAME.json) or path, validating every field."""
    s = os.fspath(name_or_path)
    path = (
        ROUTES_DIR / f"{s}.json"
        if ("/" not in s and os.sep not in s and not s.endswith(".json"))
        else Path(s)
    )
    if not path.is_file():
        raise ValueError(f"route not found: {s!r} (shipped routes: {', '.join(list_routes())})")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: invalid JSON at line {err.lineno}: {err.msg}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: the top level must be an object")
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise ValueError(f"{path}: name: expected a non-empty string, got {name!r}")
    start = data.get("start")
    pose = Pose(
        _num(start, "x", f"{path}: start"),
        _num(start, "y", f"{path}: start"),
        _num(start, "yaw", f"{path}: start"),
    )
    segs = data.get("segments")
    if not isinstance(segs, list) or not segs:
        raise ValueError(f"{path}: segments: expected a non-empty list")
    out = []
    for i, seg in enumerate(segs):
        where = f"{path}: segments[{i}]"
        v, w, d = _num(seg, "v", where), _num(seg, "w", where), _num(seg, "duration", where)
        if abs(v) > V_MAX or abs(w) > W_MAX:
            raise ValueError(f"{where}: (v={v}, w={w}) exceeds the limits |v| <= {V_MAX}, |w| <= {W_MAX}")
        if d <= 0:
            raise ValueError(f"{where}.duration: expected > 0, got {d}")
        out.append(Segment(v, w, d))
    return Route(name, pose, tuple(out))
