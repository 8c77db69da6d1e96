"""The family of procedural surfaces, floors and lights that procedural houses draw from (numpy only).

Each function takes a numpy Generator and returns map JSON (sim2d.house format), so a house is fully
described by its map and deterministic for its seed. Walls are mostly plain paint with almost no texture
(real flats), with accent walls of wallpaper, wood, tiles, bricks, stripes or a poster; furniture gets
fabric, wood and painted finishes; floors are mosaic, planks, tiles or plain, per room, with rugs.
"""

from __future__ import annotations

import colorsys
from typing import Any

import numpy as np

WALL_FAMILIES = ("paint", "wallpaper", "wood", "tiles", "bricks", "stripes", "poster", "gradient")
_WALL_P = (0.45, 0.15, 0.06, 0.07, 0.05, 0.06, 0.11, 0.05)
FLOOR_FAMILIES = ("mosaic", "planks", "tiles", "plain")


def _hsv(rng: np.random.Generator, s: tuple[float, float], v: tuple[float, float], h=None) -> list[int]:
    hue = float(rng.uniform(0, 1)) if h is None else h
    r, g, b = colorsys.hsv_to_rgb(hue, float(rng.uniform(*s)), float(rng.uniform(*v)))
    return [int(round(255 * c)) for c in (r, g, b)]


def paint_color(rng: np.random.Generator) -> list[int]:
    """Wall paint: mostly whites, creams and greys, sometimes a pastel or a strong colour."""
    pick = rng.random()
    if pick < 0.45:
        return _hsv(rng, (0.0, 0.12), (0.75, 0.97))
    if pick < 0.8:
        return _hsv(rng, (0.15, 0.4), (0.6, 0.92))
    return _hsv(rng, (0.4, 0.85), (0.35, 0.85))


def _wood(rng: np.random.Generator) -> list[list[int]]:
    base = _hsv(rng, (0.35, 0.65), (0.35, 0.8), h=float(rng.uniform(0.05, 0.11)))
    return [base, [int(c * 0.75) for c in base]]


def random_surface(
    rng: np.random.Generator, family: str | None = None, wall_height: float = 2.5
) -> dict[str, Any]:
    """One texture spec (sim2d.textures) of `family` (drawn when None)."""
    if family is None:
        family = str(rng.choice(WALL_FAMILIES, p=_WALL_P))
    a = paint_color(rng)
    if family == "paint":
        return {"kind": "solid", "colors": [a], "size": [1.0, 1.0], "grain": float(rng.uniform(0.004, 0.02))}
    if family == "wallpaper":
        b = [int(np.clip(c * rng.uniform(0.75, 0.92), 0, 255)) for c in a]
        kind = str(rng.choice(["diamonds", "dots", "stripes", "checker"]))
        s = float(rng.uniform(0.4, 0.9))
        return {
            "kind": kind,
            "colors": [a, b],
            "size": [s, s],
            "count": int(rng.integers(3, 9)),
            "grain": 0.01,
        }
    if family == "wood":
        return {"kind": "wood", "colors": _wood(rng), "size": [1.0, 1.0], "count": int(rng.integers(3, 9))}
    if family == "tiles":
        grout = [int(c * 0.7) for c in a]
        return {"kind": "tiles", "colors": [a, grout], "size": [0.6, 0.6], "count": int(rng.integers(2, 5))}
    if family == "bricks":
        brick = _hsv(rng, (0.4, 0.7), (0.45, 0.75), h=float(rng.uniform(0.0, 0.08)))
        return {"kind": "bricks", "colors": [brick, [205, 200, 190]], "size": [1.0, 0.5], "count": 4}
    if family == "stripes":
        b = paint_color(rng)
        return {"kind": "stripes", "colors": [a, b], "size": [float(rng.uniform(0.5, 1.5)), 1.0], "count": 4}
    if family == "poster":
        picture = [_hsv(rng, (0.3, 0.9), (0.3, 0.95)) for _ in range(3)]
        su = float(rng.uniform(2.0, 3.5))
        return {
            "kind": "poster",
            "colors": [a, *picture],
            "size": [su, wall_height],
            "count": int(rng.integers(2, 6)),
        }
    if family == "gradient":
        b = [int(np.clip(c * 0.8, 0, 255)) for c in a]
        return {"kind": "gradient", "colors": [a, b], "size": [float(rng.uniform(1.0, 3.0)), 1.0]}
    raise ValueError(f"unknown surface family {family!r}; known: {', '.join(WALL_FAMILIES)}")


def room_walls(rng: np.random.Generator, room: str, dims: tuple[float, float]) -> tuple[dict[str, str], dict]:
    """The n/e/s/w wall textures of a room and their specs: one finish, sometimes an accent wall."""
    main = random_surface(rng, "paint" if rng.random() < 0.6 else None)
    specs = {f"{room}_wall": main}
    faces = dict.fromkeys(("n", "e", "s", "w"), f"{room}_wall")
    if rng.random() < 0.6:
        side = str(rng.choice(["n", "e", "s", "w"]))
        specs[f"{room}_accent"] = random_surface(rng, str(rng.choice(WALL_FAMILIES[1:])))
        faces[side] = f"{room}_accent"
    return faces, specs


def furniture_palette(rng: np.random.Generator) -> dict[str, dict[str, Any]]:
    """4-7 furniture finishes shared by the house's pieces: fabric, wood, paint."""
    out = {}
    for i in range(int(rng.integers(4, 8))):
        kind = str(rng.choice(["fabric", "wood", "paint", "pattern"]))
        if kind == "fabric":
            spec = {
                "kind": "solid",
                "colors": [_hsv(rng, (0.2, 0.8), (0.25, 0.8))],
                "size": [0.5, 0.5],
                "grain": 0.07,
            }
        elif kind == "wood":
            spec = {
                "kind": "wood",
                "colors": _wood(rng),
                "size": [0.8, 0.8],
                "count": int(rng.integers(3, 8)),
            }
        elif kind == "paint":
            spec = {"kind": "solid", "colors": [paint_color(rng)], "size": [1.0, 1.0], "grain": 0.02}
        else:
            spec = {
                "kind": str(rng.choice(["stripes", "checker", "dots"])),
                "colors": [_hsv(rng, (0.3, 0.8), (0.3, 0.9)), _hsv(rng, (0.1, 0.5), (0.6, 0.95))],
                "size": [0.6, 0.6],
                "count": int(rng.integers(2, 6)),
            }
        out[f"furniture_{i}_{kind}"] = spec
    return out


def random_floor(rng: np.random.Generator, family: str | None = None) -> dict[str, Any]:
    """One floor spec (sim2d.floors) without a polygon."""
    if family is None:
        family = str(rng.choice(FLOOR_FAMILIES, p=(0.2, 0.35, 0.25, 0.2)))
    seed = int(rng.integers(0, 2**31 - 1))
    if family == "mosaic":
        return {"kind": "mosaic", "tile": float(rng.uniform(0.15, 0.4)), "seed": seed, "grout": [55, 55, 60]}
    if family == "planks":
        return {
            "kind": "planks",
            "tile": float(rng.uniform(0.1, 0.25)),
            "seed": seed,
            "colors": _wood(rng),
            "vertical": bool(rng.random() < 0.5),
        }
    if family == "tiles":
        cols = [_hsv(rng, (0.0, 0.4), (0.5, 0.95))]
        if rng.random() < 0.3:
            cols.append(_hsv(rng, (0.0, 0.4), (0.2, 0.6)))
        return {
            "kind": "tiles",
            "tile": float(rng.uniform(0.2, 0.6)),
            "seed": seed,
            "colors": cols,
            "grout": _hsv(rng, (0.0, 0.1), (0.3, 0.8)),
        }
    if family == "plain":
        return {"kind": "plain", "seed": seed, "colors": [_hsv(rng, (0.0, 0.35), (0.3, 0.8))]}
    if family == "rug":
        return {
            "kind": "rug",
            "seed": seed,
            "tile": float(rng.uniform(0.2, 0.6)),
            "colors": [_hsv(rng, (0.4, 0.9), (0.3, 0.8)), _hsv(rng, (0.2, 0.8), (0.4, 0.9))],
        }
    raise ValueError(f"unknown floor family {family!r}; known: {', '.join(FLOOR_FAMILIES)}, rug")


def floor_spec(rng: np.random.Generator, rooms: list[tuple], names: list[str]) -> dict[str, Any]:
    """A base floor, per-room floors (most rooms) and 0-3 rugs."""
    base = random_floor(rng)
    floor = {
        "tile": float(base.get("tile", 0.3)),
        "seed": int(base["seed"]),
        "grout": base.get("grout", [55, 55, 60]),
    }
    floor.update(base)
    regions = []
    for x0, y0, x1, y1 in rooms:
        if rng.random() < 0.7:
            region = random_floor(rng)
            region["polygon"] = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
            regions.append(region)
    for _ in range(int(rng.integers(0, 4))):
        x0, y0, x1, y1 = rooms[int(rng.integers(len(rooms)))]
        rw, rh = float(rng.uniform(1.0, 2.2)), float(rng.uniform(0.7, 1.6))
        if rw > x1 - x0 - 0.4 or rh > y1 - y0 - 0.4:
            continue
        cx, cy = (
            float(rng.uniform(x0 + 0.2 + rw / 2, x1 - 0.2 - rw / 2)),
            float(rng.uniform(y0 + 0.2 + rh / 2, y1 - 0.2 - rh / 2)),
        )
        region = random_floor(rng, "rug")
        region["polygon"] = [
            [cx - rw / 2, cy - rh / 2],
            [cx + rw / 2, cy - rh / 2],
            [cx + rw / 2, cy + rh / 2],
            [cx - rw / 2, cy + rh / 2],
        ]
        regions.append(region)
    floor["regions"] = regions
    return floor


def ceiling_color(rng: np.random.Generator) -> list[int]:
    return _hsv(rng, (0.0, 0.08), (0.75, 0.95))


def lighting_spec(rng: np.random.Generator, w: float, h: float) -> dict[str, Any]:
    """Global level, colour temperature (warm to cool), 1-3 lamps/windows or dim corners, maybe a gradient."""
    t = float(rng.uniform(-1.0, 1.0))  # -1 warm (tungsten), +1 cool (overcast daylight)
    tint = (
        [1.0 - 0.04 * t, 1.0 - 0.02 * abs(t), 1.0 + 0.1 * t]
        if t > 0
        else [1.0, 1.0 + 0.05 * t, 1.0 + 0.18 * t]
    )
    spots = []
    for _ in range(int(rng.integers(1, 4))):
        spots.append(
            {
                "center": [float(rng.uniform(0, w)), float(rng.uniform(0, h))],
                "radius": float(rng.uniform(1.0, 3.0)),
                "gain": float(rng.uniform(1.15, 1.5))
                if rng.random() < 0.7
                else float(rng.uniform(0.55, 0.85)),
            }
        )
    spec: dict[str, Any] = {"level": float(rng.uniform(0.7, 1.15)), "tint": tint, "spots": spots}
    if rng.random() < 0.4:
        spec["gradient"] = {
            "from": [0.0, 0.0],
            "to": [w, h] if rng.random() < 0.5 else [w, 0.0],
            "gain": [float(rng.uniform(0.6, 0.9)), 1.0],
        }
    return spec


def redrawn_floor(floor: dict[str, Any], rng: np.random.Generator) -> dict[str, Any]:
    """The same house's floor laid again: between teach and repeat a floor may be re-tiled, re-coloured or
    covered. Half the time the base keeps its kind with a new seed, tile size and grout or colours (a re-seeded
    mosaic with other grout, as `floor_recoloured` does); otherwise it becomes a random kind. Each region (room
    floors, rugs) keeps its polygon and is re-drawn, or is dropped so that the new base shows through."""
    kind = str(floor.get("kind", "mosaic"))
    if kind in FLOOR_FAMILIES and rng.random() < 0.5:
        base = random_floor(rng, kind)
        if kind == "mosaic":
            base["grout"] = _hsv(rng, (0.0, 0.6), (0.15, 0.7))
    else:
        base = random_floor(rng)
    base = {"tile": 0.3, "grout": [55, 55, 60], **base}  # the fields a base floor must have (sim2d.house)
    regions = []
    for region in floor.get("regions", []):
        if rng.random() < 0.7:
            family = "rug" if region.get("kind") == "rug" else None
            regions.append({**random_floor(rng, family), "polygon": region["polygon"]})
    if regions:
        base["regions"] = regions
    return base
