"""Appearance changes: make one house look different between teach and repeat (numpy only).

A change is a short string ``KIND:TARGET=VALUE`` (or a ``Change``); a list of them is applied, in order,
to a copy of the house map before it is built, so geometry queries, physics and the camera all agree.

=================================  ===============================================================
``retexture:NAME=SEED``            give texture NAME a new random finish (sim2d.surfaces) drawn from
                                   SEED; NAME is a texture name of the map, or ``wall`` (one wall
                                   texture picked by SEED), ``walls`` (every wall texture),
                                   ``furniture`` (one furniture texture picked by SEED) or ``floor``
                                   (the floor re-seeded: the same kinds, new tiles and colours)
``move:NAME=DIST``                 move furniture NAME (exact name, else the first name containing
                                   it) by DIST metres, in the first of 8 directions (E, NE, N, ...)
                                   where it stays inside the rooms, off the walls and off the starts
``move:NAME=DX,DY``                move it by (DX, DY) metres exactly (error if that is not possible)
``light:level=F``                  multiply the global light level by F (0.5 darker, 1.5 brighter)
``light:tint=R,G,B``               multiply the light's colour per channel (1.1,1,0.8 = warmer)
``light:dark=SIDE,GAIN``           one side darker: a gradient from GAIN at side SIDE (n, e, s or w
                                   of the house) to 1 at the opposite side (replaces any gradient)
``light:spot=X,Y,R,GAIN``          add a lamp (GAIN > 1) or a shadow (GAIN < 1) of radius R at (X, Y)
``obstacle:X,Y=SIZE``              place a SIZE x SIZE m box (0.6 m high, new texture) at (X, Y);
``obstacle:X,Y=SX,SY``             or SX x SY m. It must leave the start poses free
``floor:ROOM=SEED``                re-cover room ROOM's floor with a random kind (mosaic, planks,
``floor:X0,Y0,X1,Y1=SEED``         tiles, plain) from SEED; or the rectangle [X0, X1] x [Y0, Y1]
=================================  ===============================================================

Python API::

    from vtr.sim2d import SimConfig, Simulator
    from vtr.sim2d.appearance import Change, apply_changes, parse_change

    sim = Simulator(SimConfig(house="random:3", changes=("retexture:wall=1", "light:level=0.6")))
    data = apply_changes(map_dict, ["move:sofa=0.3"])      # a new map dict; the input is not modified
    str(Change("light", "dark", "w,0.5"))                  # "light:dark=w,0.5"

The command line takes the same strings: ``vtr sim serve --change retexture:wall=3 --change move:table=0.3``
(and ``vtr sim snapshot``). Errors are ValueError with a one-line message naming the change.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from vtr.sim2d.surfaces import random_floor, random_surface

KINDS = ("retexture", "move", "light", "obstacle", "floor")
_DIRS = [(math.cos(k * math.pi / 4), math.sin(k * math.pi / 4)) for k in range(8)]
_OBSTACLE_HEIGHT = 0.6


@dataclass(frozen=True)
class Change:
    """One appearance change; str() gives its spec string."""

    kind: str
    target: str
    value: str

    def __str__(self) -> str:
        return f"{self.kind}:{self.target}={self.value}"


def parse_change(spec: str | Change) -> Change:
    """Parse ``KIND:TARGET=VALUE``; ValueError with a one-line message if malformed."""
    if isinstance(spec, Change):
        spec = str(spec)
    if not isinstance(spec, str) or ":" not in spec or "=" not in spec:
        raise ValueError(f"bad change {spec!r}: expected KIND:TARGET=VALUE with KIND in {', '.join(KINDS)}")
    kind, rest = spec.split(":", 1)
    target, value = rest.split("=", 1)
    kind, target, value = kind.strip(), target.strip(), value.strip()
    if kind not in KINDS:
        raise ValueError(f"bad change {spec!r}: unknown kind {kind!r}; known: {', '.join(KINDS)}")
    if not target or not value:
        raise ValueError(f"bad change {spec!r}: TARGET and VALUE must not be empty")
    change = Change(kind, target, value)
    _check_syntax(change)
    return change


def _floats(change: Change, text: str, n: int | tuple[int, ...]) -> list[float]:
    counts = (n,) if isinstance(n, int) else n
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) not in counts or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"bad change {change}: expected {' or '.join(map(str, counts))} numbers in {text!r}")
    return vals


def _seed(change: Change) -> int:
    if not change.value.isdigit():
        raise ValueError(f"bad change {change}: expected an integer seed >= 0, got {change.value!r}")
    return int(change.value)


def _check_syntax(c: Change) -> None:
    if c.kind in ("retexture", "floor"):
        _seed(c)
    if c.kind == "floor" and "," in c.target:
        _floats(c, c.target, 4)
    elif c.kind == "move":
        _floats(c, c.value, (1, 2))
    elif c.kind == "obstacle":
        _floats(c, c.target, 2)
        if min(_floats(c, c.value, (1, 2))) <= 0.02:
            raise ValueError(f"bad change {c}: sizes must be > 0.02 m")
    elif c.kind == "light":
        counts = {"level": 1, "tint": 3, "spot": 4}
        if c.target == "dark":
            side, _, gain = c.value.partition(",")
            if side not in ("n", "e", "s", "w"):
                raise ValueError(f"bad change {c}: expected dark=SIDE,GAIN with SIDE in n, e, s, w")
            _floats(c, gain, 1)
        elif c.target in counts:
            vals = _floats(c, c.value, counts[c.target])
            if any(v < 0 for v in vals):
                raise ValueError(f"bad change {c}: light values must be >= 0")
        else:
            raise ValueError(f"bad change {c}: light target must be level, tint, dark or spot")


def apply_changes(data: dict[str, Any], changes: Iterable[str | Change]) -> dict[str, Any]:
    """A copy of house map `data` with `changes` applied in order (the input is not modified)."""
    out = copy.deepcopy(data)
    for spec in changes:
        c = parse_change(spec)
        {"retexture": _retexture, "move": _move, "light": _light, "obstacle": _obstacle, "floor": _floor}[
            c.kind
        ](out, c)
    return out


# --------------------------------------------------------------------------------------------- changes
def _wall_textures(data: dict[str, Any]) -> list[str]:
    return sorted({t for r in data["rooms"] for t in r["walls"].values()})


def _retexture(data: dict[str, Any], c: Change) -> None:
    rng = np.random.default_rng([_seed(c), 17])
    if c.target == "floor":
        floor = data["floor"]
        floor["seed"] = int(rng.integers(0, 2**31 - 1))
        for i, region in enumerate(floor.get("regions", [])):
            region["seed"] = int(rng.integers(0, 2**31 - 1)) + i
            if "colors" in region and region.get("kind") != "rug":
                region["colors"] = random_floor(rng, region.get("kind", "plain")).get(
                    "colors", region["colors"]
                )
        return
    walls = _wall_textures(data)
    if c.target == "walls":
        names = walls
    elif c.target == "wall":
        names = [walls[int(rng.integers(len(walls)))]]
    elif c.target == "furniture":
        used = sorted({f["texture"] for f in data.get("furniture", [])})
        if not used:
            raise ValueError(f"change {c}: the house has no furniture")
        names = [used[int(rng.integers(len(used)))]]
    elif c.target in data["textures"]:
        names = [c.target]
    else:
        raise ValueError(
            f"change {c}: unknown texture {c.target!r}; known: {', '.join(sorted(data['textures']))}"
        )
    for name in names:
        old = data["textures"][name]
        while True:  # a different family or colour than before
            new = random_surface(rng)
            if new != old:
                break
        data["textures"][name] = new


def _furniture_index(data: dict[str, Any], c: Change) -> int:
    names = [f["name"] for f in data.get("furniture", [])]
    if c.target in names:
        return names.index(c.target)
    for i, n in enumerate(names):
        if c.target in n:
            return i
    raise ValueError(f"change {c}: no furniture named like {c.target!r}; known: {', '.join(names)}")


def _shifted(piece: dict[str, Any], dx: float, dy: float) -> dict[str, Any]:
    p = copy.deepcopy(piece)
    if "points" in p:
        p["points"] = [[x + dx, y + dy] for x, y in p["points"]]
    else:
        p["center"] = [p["center"][0] + dx, p["center"][1] + dy]
    return p


def _fits(data: dict[str, Any], index: int) -> bool:
    """Whether furniture `index` lies inside the rooms, off the walls and every start pose stays free."""
    from vtr.sim2d.house import House, HouseError

    try:
        house = House(_geometry_only(data), "check")
    except HouseError:
        return False  # a start pose is no longer free
    f = house.furniture[index]
    pts = np.concatenate([f.vertices, (f.vertices + np.roll(f.vertices, -1, axis=0)) / 2])
    a, ab, inv_len2, poly_id, _, _ = house._edges
    wall_edges = poly_id < len(house.wall_boxes)
    for x, y in pts:
        if house.room_at(x, y) is None:
            return False
        ap = np.array([x, y]) - a[wall_edges]
        t = np.clip(np.einsum("ij,ij->i", ap, ab[wall_edges]) * inv_len2[wall_edges], 0.0, 1.0)
        if np.min(np.hypot(*(ap - ab[wall_edges] * t[:, None]).T)) < 0.02:
            return False
    return True


def _geometry_only(data: dict[str, Any]) -> dict[str, Any]:
    """The map with one plain texture and floor, so that checking geometry does not build textures."""
    tex = {"kind": "solid", "colors": [[128, 128, 128]]}
    d = dict(data, textures=dict.fromkeys(data["textures"], tex), lighting=None)
    d["floor"] = {"tile": 2.0, "seed": 0, "grout": [0, 0, 0], "kind": "plain"}
    return d


def _move(data: dict[str, Any], c: Change) -> None:
    i = _furniture_index(data, c)
    vals = _floats(c, c.value, (1, 2))
    piece = data["furniture"][i]
    tries = [(vals[0], vals[1])] if len(vals) == 2 else [(vals[0] * dx, vals[0] * dy) for dx, dy in _DIRS]
    for dx, dy in tries:
        data["furniture"][i] = _shifted(piece, dx, dy)
        if _fits(data, i):
            return
    data["furniture"][i] = piece
    raise ValueError(
        f"change {c}: {piece['name']} cannot move there (walls, rooms or a start pose in the way)"
    )


def _light(data: dict[str, Any], c: Change) -> None:
    light = copy.deepcopy(data.get("lighting") or {})
    if c.target == "level":
        light["level"] = float(light.get("level", 1.0)) * float(c.value)
    elif c.target == "tint":
        tint = light.get("tint", [1.0, 1.0, 1.0])
        light["tint"] = [a * b for a, b in zip(tint, _floats(c, c.value, 3), strict=True)]
    elif c.target == "spot":
        x, y, r, gain = _floats(c, c.value, 4)
        light.setdefault("spots", []).append({"center": [x, y], "radius": r, "gain": gain})
    else:  # dark=SIDE,GAIN
        side, _, gain = c.value.partition(",")
        pts = np.concatenate([np.asarray(r["polygon"], dtype=float) for r in data["rooms"]])
        (x0, y0), (x1, y1) = pts.min(axis=0), pts.max(axis=0)
        xm, ym = (x0 + x1) / 2, (y0 + y1) / 2
        start = {"n": [xm, y1], "s": [xm, y0], "e": [x1, ym], "w": [x0, ym]}[side]
        end = {"n": [xm, y0], "s": [xm, y1], "e": [x0, ym], "w": [x1, ym]}[side]
        light["gradient"] = {"from": start, "to": end, "gain": [float(gain), 1.0]}
    data["lighting"] = light


def _obstacle(data: dict[str, Any], c: Change) -> None:
    x, y = _floats(c, c.target, 2)
    size = _floats(c, c.value, (1, 2))
    sx, sy = (size[0], size[0]) if len(size) == 1 else size
    k = sum(1 for f in data.get("furniture", []) if f["name"].startswith("obstacle"))
    tex = f"obstacle_{k}"
    data["textures"][tex] = random_surface(np.random.default_rng([k, int(x * 1000), int(y * 1000)]))
    data.setdefault("furniture", []).append(
        {
            "name": tex,
            "shape": "box",
            "center": [x, y],
            "size": [sx, sy],
            "height": _OBSTACLE_HEIGHT,
            "texture": tex,
        }
    )
    if not _fits(data, len(data["furniture"]) - 1):
        data["furniture"].pop()
        raise ValueError(f"change {c}: the obstacle would cover a start pose, a wall or leave the rooms")


def _floor(data: dict[str, Any], c: Change) -> None:
    rng = np.random.default_rng([_seed(c), 23])
    if "," in c.target:
        x0, y0, x1, y1 = _floats(c, c.target, 4)
        poly = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    else:
        rooms = {r["name"]: r["polygon"] for r in data["rooms"]}
        if c.target not in rooms:
            raise ValueError(f"change {c}: unknown room {c.target!r}; known: {', '.join(rooms)}")
        poly = rooms[c.target]
    region = random_floor(rng)
    region["polygon"] = poly
    data["floor"].setdefault("regions", []).append(region)
