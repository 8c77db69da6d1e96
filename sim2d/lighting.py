"""Lighting of a house: a global level, a colour cast and darker or brighter regions (numpy only).

A house map may hold an optional ``lighting`` object (absent: level 1, white light, no regions)::

    "lighting": {
        "level": 1.0,                         # global multiplier on every surface
        "tint": [1.0, 0.95, 0.85],            # per-channel multiplier (colour temperature: warm < 1 in blue)
        "spots": [{"center": [x, y], "radius": 1.5, "gain": 1.4}],   # a lamp or window: x gain at centre
        "gradient": {"from": [x0, y0], "to": [x1, y1], "gain": [0.6, 1.0]}  # one side darker
    }

The light at a floor point is ``level * gradient(x, y) * prod(1 + (gain - 1) * exp(-(d / radius)^2))``.
The renderer bakes it into what it precomputes, so it costs nothing per frame: the floor image is lit per
texel, and each wall or furniture face takes the light at its midpoint (rounded to 1/16 steps, so faces
in similar light share one shaded texture copy). The tint and level also scale the ceiling.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

LIGHT_STEP = 1.0 / 16.0  # faces' light is rounded to this step (shared shaded copies in the atlas)


def _number(value: Any, where: str, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where}: expected a finite number, got {value!r}")
    if not lo <= value <= hi:
        raise ValueError(f"{where}: expected a number in [{lo}, {hi}], got {value!r}")
    return float(value)


def _point(value: Any, where: str) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise ValueError(f"{where}: expected [x, y], got {value!r}")
    return (_number(value[0], where, -1e4, 1e4), _number(value[1], where, -1e4, 1e4))


@dataclass(frozen=True)
class Spot:
    center: tuple[float, float]
    radius: float
    gain: float


@dataclass(frozen=True)
class Lighting:
    """Validated lighting of a house (see the module docstring for the JSON form)."""

    level: float = 1.0
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    spots: tuple[Spot, ...] = field(default_factory=tuple)
    gradient: tuple[tuple[float, float], tuple[float, float], float, float] | None = None

    @classmethod
    def from_spec(cls, spec: Any, where: str = "lighting") -> Lighting:
        if spec is None:
            return cls()
        if not isinstance(spec, dict):
            raise ValueError(f"{where}: expected an object, got {spec!r}")
        unknown = set(spec) - {"level", "tint", "spots", "gradient"}
        if unknown:
            raise ValueError(f"{where}: unknown fields {sorted(unknown)}")
        level = _number(spec.get("level", 1.0), f"{where}.level", 0.05, 4.0)
        tint_v = spec.get("tint", [1.0, 1.0, 1.0])
        if not isinstance(tint_v, (list, tuple)) or len(tint_v) != 3:
            raise ValueError(f"{where}.tint: expected [r, g, b] multipliers, got {tint_v!r}")
        tint = tuple(_number(c, f"{where}.tint", 0.0, 4.0) for c in tint_v)
        spots = []
        for i, s in enumerate(spec.get("spots", [])):
            w = f"{where}.spots[{i}]"
            if not isinstance(s, dict):
                raise ValueError(f"{w}: expected an object, got {s!r}")
            spots.append(
                Spot(
                    _point(s.get("center"), f"{w}.center"),
                    _number(s.get("radius"), f"{w}.radius", 0.05, 100.0),
                    _number(s.get("gain"), f"{w}.gain", 0.0, 4.0),
                )
            )
        gradient = None
        if spec.get("gradient") is not None:
            g = spec["gradient"]
            w = f"{where}.gradient"
            if not isinstance(g, dict) or not isinstance(g.get("gain"), (list, tuple)) or len(g["gain"]) != 2:
                raise ValueError(
                    f"{w}: expected {{'from': [x, y], 'to': [x, y], 'gain': [g0, g1]}}, got {g!r}"
                )
            p0, p1 = _point(g.get("from"), f"{w}.from"), _point(g.get("to"), f"{w}.to")
            if math.hypot(p1[0] - p0[0], p1[1] - p0[1]) < 1e-3:
                raise ValueError(f"{w}: 'from' and 'to' must differ")
            g0, g1 = (_number(v, f"{w}.gain", 0.0, 4.0) for v in g["gain"])
            gradient = (p0, p1, g0, g1)
        return cls(level, tint, tuple(spots), gradient)  # type: ignore[arg-type]

    def to_spec(self) -> dict[str, Any]:
        out: dict[str, Any] = {"level": self.level, "tint": list(self.tint)}
        out["spots"] = [{"center": list(s.center), "radius": s.radius, "gain": s.gain} for s in self.spots]
        if self.gradient is not None:
            p0, p1, g0, g1 = self.gradient
            out["gradient"] = {"from": list(p0), "to": list(p1), "gain": [g0, g1]}
        return out

    @property
    def is_uniform(self) -> bool:
        return not self.spots and self.gradient is None

    def at(self, xy: np.ndarray) -> np.ndarray:
        """Light level (without tint) at points xy (..., 2)."""
        xy = np.asarray(xy, dtype=np.float64)
        light = np.full(xy.shape[:-1], self.level)
        if self.gradient is not None:
            (x0, y0), (x1, y1), g0, g1 = self.gradient
            d = np.array([x1 - x0, y1 - y0])
            t = np.clip(((xy[..., 0] - x0) * d[0] + (xy[..., 1] - y0) * d[1]) / float(d @ d), 0.0, 1.0)
            light = light * (g0 + (g1 - g0) * t)
        for s in self.spots:
            d2 = (xy[..., 0] - s.center[0]) ** 2 + (xy[..., 1] - s.center[1]) ** 2
            light = light * (1.0 + (s.gain - 1.0) * np.exp(-d2 / (s.radius * s.radius)))
        return light

    def face_levels(self, midpoints: np.ndarray) -> np.ndarray:
        """Light of each face (by its midpoint), rounded to LIGHT_STEP."""
        return np.maximum(np.round(self.at(midpoints) / LIGHT_STEP) * LIGHT_STEP, LIGHT_STEP)

    def light_image(self, image: np.ndarray, origin: tuple[float, float], extent: float) -> np.ndarray:
        """A floor image (n, n, 3) uint8 (row = y, column = x) lit per texel; the tint applies later."""
        if self.is_uniform:
            return image  # the level is applied with the tint (one multiply in the atlas)
        n = image.shape[0]
        c = origin[0] + (np.arange(n) + 0.5) * extent / n, origin[1] + (np.arange(n) + 0.5) * extent / n
        px, py = np.meshgrid(c[0], c[1], indexing="xy")
        gain = self.at(np.stack([px, py], axis=-1)) / self.level
        return np.clip(image * gain[..., None], 0, 255).astype(np.uint8)
