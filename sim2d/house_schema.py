"""Validation of house map fields (numpy only): readers that raise HouseError naming the file and field."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

CIRCLE_SIDES = 16  # circles are drawn as polygons with this many faces (physics uses the true circle)


class HouseError(ValueError):
    """A house file is missing something or holds a bad value; the message names the file and field."""


@dataclass(frozen=True)
class Furniture:
    name: str
    shape: str  # "box" | "polygon" | "circle"
    height: float
    texture: str
    vertices: np.ndarray  # (K, 2) convex polygon (box/polygon); the drawn polygon for a circle
    center: tuple[float, float]
    radius: float  # circles only, 0.0 otherwise


def _points(value: Any, where: str, n: int | None = None) -> np.ndarray:
    ok = isinstance(value, list) and all(
        isinstance(p, list)
        and len(p) == 2
        and all(isinstance(c, (int, float)) and math.isfinite(c) for c in p)
        for p in value
    )
    if not ok or (n is not None and len(value) != n):
        count = f"{n} " if n is not None else ""
        raise HouseError(f"{where}: expected a list of {count}[x, y] points, got {value!r}")
    return np.asarray(value, dtype=np.float64)


def _signed_area(poly: np.ndarray) -> float:
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _is_convex(poly: np.ndarray) -> bool:
    d1 = np.roll(poly, -1, axis=0) - poly
    d2 = np.roll(d1, -1, axis=0)
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    return bool(np.all(cross > 1e-12) or np.all(cross < -1e-12))


class _Validator:
    """Field readers that raise HouseError naming the file and the field."""

    def __init__(self, source: str) -> None:
        self.source = source

    def _get(self, obj: Any, key: str, where: str | None) -> Any:
        path = f"{where}.{key}" if where else key
        if not isinstance(obj, dict):
            raise HouseError(f"{self.source}: {where or 'top level'}: expected an object, got {obj!r}")
        if key not in obj:
            raise HouseError(f"{self.source}: {path}: missing required field")
        return obj[key]

    def _fail(self, key: str, where: str | None, expected: str, value: Any) -> HouseError:
        path = f"{where}.{key}" if where else key
        return HouseError(f"{self.source}: {path}: expected {expected}, got {value!r}")

    def string(self, obj: Any, key: str, where: str | None = None) -> str:
        value = self._get(obj, key, where)
        if not isinstance(value, str) or not value:
            raise self._fail(key, where, "a non-empty string", value)
        return value

    def number(
        self, obj: Any, key: str, lo: float = -math.inf, hi: float = math.inf, where: str | None = None
    ) -> float:
        value = self._get(obj, key, where)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self._fail(key, where, "a finite number", value)
        if not lo <= value <= hi:
            raise self._fail(key, where, f"a number in [{lo}, {hi}]", value)
        return float(value)

    def integer(self, obj: Any, key: str, where: str | None = None) -> int:
        value = self._get(obj, key, where)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self._fail(key, where, "an integer", value)
        return value

    def color(self, obj: Any, key: str, where: str | None = None) -> np.ndarray:
        value = self._get(obj, key, where)
        if (
            not isinstance(value, list)
            or len(value) != 3
            or not all(isinstance(c, (int, float)) and 0 <= c <= 255 for c in value)
        ):
            raise self._fail(key, where, "an [r, g, b] colour with values in 0..255", value)
        return np.asarray(value, dtype=np.float64)

    def mapping(self, obj: Any, key: str, where: str | None = None) -> dict[str, Any]:
        value = self._get(obj, key, where)
        if not isinstance(value, dict):
            raise self._fail(key, where, "an object", value)
        return value

    def list(self, obj: Any, key: str, min_len: int, where: str | None = None) -> list[Any]:
        value = self._get(obj, key, where)
        if not isinstance(value, list) or len(value) < min_len:
            raise self._fail(key, where, f"a list of at least {min_len} entries", value)
        return value

    def texture_ref(self, obj: Any, key: str, tex_index: dict[str, int], where: str | None = None) -> int:
        name = self.string(obj, key, where)
        if name not in tex_index:
            raise self._fail(
                key, where, f"a texture name defined in 'textures' ({', '.join(tex_index)})", name
            )
        return tex_index[name]

    def polygon(self, obj: Any, key: str, where: str | None = None) -> np.ndarray:
        path = f"{where}.{key}" if where else key
        poly = _points(self._get(obj, key, where), f"{self.source}: {path}")
        if len(poly) < 3 or abs(_signed_area(poly)) < 1e-6:
            raise HouseError(f"{self.source}: {path}: a polygon needs at least 3 points and a non-zero area")
        return poly

    def furniture(self, f: Any, where: str, tex_index: dict[str, int]) -> Furniture:
        name = self.string(f, "name", where)
        shape = self.string(f, "shape", where)
        height = self.number(f, "height", lo=0.05, hi=5.0, where=where)
        texture = self.string(f, "texture", where)
        self.texture_ref(f, "texture", tex_index, where)
        radius = 0.0
        if shape == "box":
            c = _points([self._get(f, "center", where)], f"{self.source}: {where}.center")[0]
            size = _points([self._get(f, "size", where)], f"{self.source}: {where}.size")[0]
            if np.any(size <= 0.01):
                raise self._fail("size", where, "two sizes > 0.01 m", f["size"])
            ang = math.radians(self.number(f, "angle_deg", where=where)) if "angle_deg" in f else 0.0
            hx, hy = size / 2
            local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
            rot = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
            verts = local @ rot.T + c
        elif shape == "polygon":
            verts = self.polygon(f, "points", where)
            if not _is_convex(verts):
                raise HouseError(
                    f"{self.source}: {where}.points: the polygon must be convex (split it into pieces)"
                )
            if _signed_area(verts) < 0:
                verts = verts[::-1].copy()
            c = verts.mean(axis=0)
        elif shape == "circle":
            c = _points([self._get(f, "center", where)], f"{self.source}: {where}.center")[0]
            radius = self.number(f, "radius", lo=0.02, hi=5.0, where=where)
            ang = np.arange(CIRCLE_SIDES) * (2 * math.pi / CIRCLE_SIDES)
            # Vertices on a slightly larger circle so the drawn polygon encloses the physical disc.
            r_draw = radius / math.cos(math.pi / CIRCLE_SIDES)
            verts = c + r_draw * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        else:
            raise self._fail("shape", where, "'box', 'polygon' or 'circle'", shape)
        return Furniture(
            name,
            shape,
            height,
            texture,
            np.asarray(verts, dtype=np.float64),
            (float(c[0]), float(c[1])),
            radius,
        )
