"""Procedural houses: a valid, deterministic house map from a seed (numpy only).

``--house random:SEED`` (any integer >= 0) builds a house in the map format of sim2d.house:

- layout: a rectangle split recursively (binary space partition) into 3-8 rooms of at least 2.4 m a side;
  every split line gets one doorway, away from the walls that meet it, so the rooms form a connected tree
  (each half of a split is connected by induction, the doorway joins the halves);
- surfaces (sim2d.surfaces): per room one wall finish, often plain paint with almost no texture as in real
  flats, sometimes an accent wall (wallpaper, wood, tiles, bricks, a poster); a furniture palette;
- floors (sim2d.floors): a base kind and per-room floors (mosaic, planks, tiles, plain), plus rugs;
- furniture: sofas, beds, wardrobes, shelves, tables, round tables, armchairs, plants, sideboards, as boxes,
  circles and convex polygons, 0.42-2.2 m high; rugs are painted on the floor. Pieces are always taller than
  the camera (0.3 m): the two-layer renderer draws vertical faces only, so low solid pieces whose top would
  show are not generated (rugs and mats are the low things, seen from above, exactly, as floor paint);
- lighting (sim2d.lighting): a global level, a colour temperature, lamps/windows and sometimes one side
  darker.

Validity: every piece of furniture is accepted only if the free space (a 0.1 m grid of points where a disc
of FREE_RADIUS fits) stays connected through every room; the start poses (one per room) are the most open
reachable points of each room. A layout that fails is redrawn from a derived seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from vtr.sim2d.surfaces import ceiling_color, floor_spec, furniture_palette, lighting_spec, room_walls

WALL_T = 0.1  # wall thickness (m)
MIN_ROOM = 2.4  # shortest room side (m)
FREE_RADIUS = 0.3  # free space must fit a disc this wide (robot 0.17 m + collection clearance)
GRID = 0.1  # m between points of the free-space grid
MAX_SEED = 2**31 - 1


def parse_random_seed(name: str) -> int:
    """The SEED of ``random:SEED``; ValueError with a one-line message otherwise."""
    text = name.split(":", 1)[1] if ":" in name else ""
    if not text.isdigit() or int(text) > MAX_SEED:
        raise ValueError(f"bad house {name!r}: expected random:SEED with SEED an integer in 0..{MAX_SEED}")
    return int(text)


@dataclass
class _Split:
    vertical: bool  # a line x = c (True) or y = c (False)
    c: float
    lo: float  # extent along the line
    hi: float


def _layout(rng: np.random.Generator, n_rooms: int) -> tuple[list[tuple], list[_Split], float, float]:
    area = n_rooms * rng.uniform(10.0, 18.0)
    aspect = rng.uniform(1.0, 1.7)
    w, h = math.sqrt(area * aspect), math.sqrt(area / aspect)
    leaves = [(0.0, 0.0, w, h)]
    splits: list[_Split] = []
    while len(leaves) < n_rooms:
        order = sorted(
            range(len(leaves)), key=lambda i: -(leaves[i][2] - leaves[i][0]) * (leaves[i][3] - leaves[i][1])
        )
        for i in order:
            x0, y0, x1, y1 = leaves[i]
            vertical = (x1 - x0) >= (y1 - y0)
            span = (x1 - x0) if vertical else (y1 - y0)
            if span < 2 * MIN_ROOM:
                continue
            lo = (x0 if vertical else y0) + MIN_ROOM
            hi = (x1 if vertical else y1) - MIN_ROOM
            c = round(float(rng.uniform(lo, hi)) * 20) / 20  # 5 cm grid: tidy numbers in the map
            leaves.pop(i)
            if vertical:
                leaves += [(x0, y0, c, y1), (c, y0, x1, y1)]
                splits.append(_Split(True, c, y0, y1))
            else:
                leaves += [(x0, y0, x1, c), (x0, c, x1, y1)]
                splits.append(_Split(False, c, x0, x1))
            break
        else:
            break  # nothing left to split
    return leaves, splits, w, h


def _walls_and_doors(splits: list[_Split], w: float, h: float, rng: np.random.Generator) -> tuple[list, list]:
    """Wall centrelines (split at every junction, so that each piece borders one room per side) and doors."""
    lines = [
        _Split(False, 0.0, 0.0, w),
        _Split(False, h, 0.0, w),
        _Split(True, 0.0, 0.0, h),
        _Split(True, w, 0.0, h),
    ]
    all_lines = lines + splits
    walls, doors = [], []
    for li, line in enumerate(all_lines):
        # Positions along this line where another line ends on it (T-junctions).
        cuts = {line.lo, line.hi}
        for other in all_lines:
            if other.vertical != line.vertical and line.lo - 1e-9 <= other.c <= line.hi + 1e-9:
                if abs(other.lo - line.c) < 1e-9 or abs(other.hi - line.c) < 1e-9:
                    cuts.add(other.c)
        cuts_s = sorted(cuts)
        pieces = list(zip(cuts_s[:-1], cuts_s[1:], strict=True))
        if li >= 4:  # a split line: one doorway in a piece long enough for it
            width = float(rng.uniform(0.85, 1.1))
            margin = 0.25
            fits = [p for p in pieces if p[1] - p[0] >= width + 2 * margin]
            a, b = fits[int(rng.integers(len(fits)))]
            d0 = round(float(rng.uniform(a + margin, b - margin - width)) * 20) / 20
            d1 = d0 + width
            pieces = [p for p in pieces if p != (a, b)] + [(a, d0), (d1, b)]
            mid = (d0 + d1) / 2
            doors.append(((line.c, mid) if line.vertical else (mid, line.c), width))
        for a, b in pieces:
            if b - a > 1e-6:
                walls.append([[line.c, a], [line.c, b]] if line.vertical else [[a, line.c], [b, line.c]])
    return walls, doors


_ROOM_KINDS = ("living", "kitchen", "bedroom", "study", "bath", "hall", "dining", "play")
# (name, shape, size range x, size range y, height range, against a wall)
_PIECES = {
    "sofa": ("box", (1.6, 2.2), (0.8, 0.95), (0.75, 0.9), True),
    "bed": ("box", (1.4, 1.9), (1.9, 2.1), (0.45, 0.6), True),
    "wardrobe": ("box", (0.9, 2.0), (0.55, 0.65), (1.8, 2.2), True),
    "shelf": ("box", (0.6, 1.2), (0.3, 0.4), (0.8, 2.0), True),
    "sideboard": ("poly", (1.0, 1.6), (0.4, 0.55), (0.6, 0.9), True),
    "table": ("box", (0.8, 1.6), (0.7, 0.9), (0.72, 0.78), False),
    "round_table": ("circle", (0.4, 0.6), (0.0, 0.0), (0.72, 0.76), False),
    "armchair": ("box", (0.7, 0.9), (0.7, 0.9), (0.7, 0.9), False),
    "plant": ("circle", (0.15, 0.3), (0.0, 0.0), (0.6, 1.5), False),
}
_ROOM_PIECES = {
    "living": ("sofa", "armchair", "table", "shelf", "plant", "sideboard"),
    "kitchen": ("table", "round_table", "sideboard", "shelf", "wardrobe"),
    "bedroom": ("bed", "wardrobe", "shelf", "plant", "armchair"),
    "study": ("table", "shelf", "wardrobe", "armchair", "plant"),
    "bath": ("shelf", "sideboard", "plant"),
    "hall": ("shelf", "wardrobe", "plant", "sideboard"),
    "dining": ("table", "round_table", "sideboard", "plant", "shelf"),
    "play": ("shelf", "round_table", "armchair", "plant", "sideboard"),
}


def _piece(kind: str, rect: tuple, rng: np.random.Generator) -> tuple[dict[str, Any], np.ndarray] | None:
    """A candidate piece in room `rect` and its outline (polygon; circles as 16-gons)."""
    shape, sx, sy, sh, on_wall = _PIECES[kind]
    x0, y0, x1, y1 = (rect[0] + WALL_T / 2, rect[1] + WALL_T / 2, rect[2] - WALL_T / 2, rect[3] - WALL_T / 2)
    height = round(float(rng.uniform(*sh)), 2)
    if shape == "circle":
        r = round(float(rng.uniform(*sx)), 2)
        m = r + 0.6
        if x1 - x0 <= 2 * m or y1 - y0 <= 2 * m:
            return None
        cx, cy = float(rng.uniform(x0 + m, x1 - m)), float(rng.uniform(y0 + m, y1 - m))
        ang = np.arange(16) * (2 * math.pi / 16)
        r_out = r / math.cos(math.pi / 16)  # the 16-gon around the disc, as the renderer draws it
        outline = np.stack([cx + r_out * np.cos(ang), cy + r_out * np.sin(ang)], axis=1)
        return {
            "shape": "circle",
            "center": [round(cx, 3), round(cy, 3)],
            "radius": r,
            "height": height,
        }, outline
    a, b = float(rng.uniform(*sx)), float(rng.uniform(*sy))  # a along the wall, b away from it
    if on_wall:
        side = int(rng.integers(4))
        gap = float(rng.uniform(0.02, 0.08))
        if side in (0, 1):  # south / north wall: the piece runs along x
            if x1 - x0 < a + 0.1:
                return None
            cx = float(rng.uniform(x0 + a / 2, x1 - a / 2))
            cy = y0 + gap + b / 2 if side == 0 else y1 - gap - b / 2
            hx, hy = a / 2, b / 2
        else:  # west / east wall: the piece runs along y
            if y1 - y0 < a + 0.1:
                return None
            cy = float(rng.uniform(y0 + a / 2, y1 - a / 2))
            cx = x0 + gap + b / 2 if side == 2 else x1 - gap - b / 2
            hx, hy = b / 2, a / 2
        ang = 0.0
    else:
        cx, cy = float(rng.uniform(x0 + 0.9, x1 - 0.9)), float(rng.uniform(y0 + 0.9, y1 - 0.9))
        hx, hy = a / 2, b / 2
        ang = float(rng.uniform(-45.0, 45.0)) if kind == "armchair" else float(rng.choice([0.0, 90.0]))
    rot = math.radians(ang)
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    if shape == "poly":  # a sideboard with chamfered corners: a convex octagon, the same any way round
        c = min(hx, hy) * 0.4
        local = np.array(
            [
                [-hx + c, -hy],
                [hx - c, -hy],
                [hx, -hy + c],
                [hx, hy - c],
                [hx - c, hy],
                [-hx + c, hy],
                [-hx, hy - c],
                [-hx, -hy + c],
            ]
        )
    rm = np.array([[math.cos(rot), -math.sin(rot)], [math.sin(rot), math.cos(rot)]])
    outline = local @ rm.T + (cx, cy)
    pts = [[round(float(p[0]), 3), round(float(p[1]), 3)] for p in outline]
    return {"shape": "polygon", "points": pts, "height": height}, np.asarray(pts)


def _poly_distance(poly: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Distance from grid points to a polygon (0 inside)."""
    best = np.full(px.shape, np.inf)
    inside = np.zeros(px.shape, dtype=bool)
    for k in range(len(poly)):
        (ax, ay), (bx, by) = poly[k], poly[(k + 1) % len(poly)]
        ex, ey = bx - ax, by - ay
        t = np.clip(((px - ax) * ex + (py - ay) * ey) / max(ex * ex + ey * ey, 1e-12), 0.0, 1.0)
        best = np.minimum(best, np.hypot(px - ax - t * ex, py - ay - t * ey))
        if ay != by:
            inside ^= ((ay > py) != (by > py)) & (px < ax + (py - ay) * ex / ey)
    return np.where(inside, 0.0, best)


def _flood(start: tuple[int, int], free: np.ndarray) -> np.ndarray:
    reach = np.zeros_like(free)
    reach[start] = True
    while True:
        grown = reach.copy()
        grown[1:] |= reach[:-1]
        grown[:-1] |= reach[1:]
        grown[:, 1:] |= reach[:, :-1]
        grown[:, :-1] |= reach[:, 1:]
        grown &= free
        if np.array_equal(grown, reach):
            return reach
        reach = grown


def _connected(free: np.ndarray, room_id: np.ndarray, n_rooms: int, max_parts: int = 30) -> np.ndarray | None:
    """The component of free grid points (4-connected) reaching every room, or None if none does.

    Pockets (behind furniture, in corners) are components too: they are tried and skipped."""
    left = free.copy()
    for _ in range(max_parts):
        cells = np.argwhere(left)
        if len(cells) == 0:
            return None
        reach = _flood(tuple(cells[0]), free)
        if np.count_nonzero(np.unique(room_id[reach]) >= 0) == n_rooms:
            return reach
        left &= ~reach
    return None


def generate_house_data(seed: int, attempts: int = 20) -> dict[str, Any]:
    """The map (a JSON-like dict for sim2d.house.House) of procedural house `seed`; same seed, same house."""
    for attempt in range(attempts):
        data = _try_generate(np.random.default_rng([seed, attempt, 9]), seed)
        if data is not None:
            return data
    raise RuntimeError(f"procedural house {seed}: no valid layout in {attempts} attempts")


def _try_generate(rng: np.random.Generator, seed: int) -> dict[str, Any] | None:
    n_rooms = int(rng.integers(3, 9))
    leaves, splits, w, h = _layout(rng, n_rooms)
    walls, doors = _walls_and_doors(splits, w, h, rng)
    kinds = ["living"] + [str(k) for k in rng.choice(_ROOM_KINDS[1:], size=len(leaves) - 1)]
    order = sorted(
        range(len(leaves)), key=lambda i: -(leaves[i][2] - leaves[i][0]) * (leaves[i][3] - leaves[i][1])
    )
    names = [""] * len(leaves)
    for rank, i in enumerate(order):
        names[i] = f"{kinds[rank]}{rank}"
    textures: dict[str, Any] = {}
    rooms = []
    for i, rect in enumerate(leaves):
        x0, y0, x1, y1 = rect
        faces, specs = room_walls(rng, names[i], (x1 - x0, y1 - y0))
        textures.update(specs)
        rooms.append({"name": names[i], "polygon": [[x0, y0], [x1, y0], [x1, y1], [x0, y1]], "walls": faces})
    palette = furniture_palette(rng)
    textures.update(palette)
    textures["door_jamb"] = {"kind": "wood", "colors": [[170, 130, 90], [130, 95, 60]], "size": [0.5, 1.0]}

    # Free-space grid: inside the house, away from walls and doorway-free; furniture is then added one by one.
    gx = np.arange(GRID / 2, w, GRID)
    gy = np.arange(GRID / 2, h, GRID)
    px, py = np.meshgrid(gx, gy, indexing="xy")
    room_id = np.full(px.shape, -1)
    for i, (x0, y0, x1, y1) in enumerate(leaves):
        room_id[(px >= x0) & (px < x1) & (py >= y0) & (py < y1)] = i
    clear = np.full(px.shape, np.inf)
    for (ax, ay), (bx, by) in walls:
        box = np.array([[ax, ay], [bx, ay], [bx, by], [ax, by]], dtype=np.float64)
        box = box + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * (WALL_T / 2)
        clear = np.minimum(clear, _poly_distance(box, px, py))
    free = clear >= FREE_RADIUS
    if _connected(free, room_id, len(leaves)) is None:
        return None
    near_door = np.zeros(px.shape, dtype=bool)
    for (dx, dy), dw in doors:
        near_door |= np.hypot(px - dx, py - dy) < dw / 2 + 0.7
    furniture = []
    for i, rect in enumerate(leaves):
        kind_pool = _ROOM_PIECES[names[i].rstrip("0123456789")]
        area = (rect[2] - rect[0]) * (rect[3] - rect[1])
        target, placed = int(rng.integers(2, 3 + min(5, int(area / 5)))), 0
        for j in range(4 * target):  # rejection sampling: a few candidates per piece kept
            if placed == target:
                break
            kind = str(rng.choice(kind_pool))
            cand = _piece(kind, rect, rng)
            if cand is None:
                continue
            spec, outline = cand
            dist = _poly_distance(outline, px, py)
            if np.any((dist < 0.05) & near_door) or np.any((dist <= 0.0) & (clear < 0.02)):
                continue  # blocks a doorway or overlaps a wall
            if any(np.any((dist < 0.08) & (f["_dist"] <= 0.0)) for f in furniture):
                continue  # overlaps another piece
            trial = free & (dist >= FREE_RADIUS)
            if _connected(trial, room_id, len(leaves)) is None:
                continue
            free = trial
            placed += 1
            spec = {"name": f"{kind}_{names[i]}_{j}", "texture": str(rng.choice(list(palette))), **spec}
            spec["_dist"] = dist
            furniture.append(spec)
    reach = _connected(free, room_id, len(leaves))
    if reach is None:
        return None
    clearance = np.where(reach, np.minimum(clear, 1.5), 0.0)
    for f in furniture:
        clearance = np.minimum(clearance, f.pop("_dist"))
    start_poses = []
    for i, _rect in enumerate(leaves):
        cells = np.argwhere(reach & (room_id == i))
        if len(cells) == 0:
            return None
        # The most open reachable point of the room (ties: the first in grid order), facing a random way.
        score = clearance[cells[:, 0], cells[:, 1]] + 0.01 * rng.random(len(cells))
        r, c = cells[int(np.argmax(score))]
        yaw = round(float(rng.uniform(-math.pi, math.pi)), 3)
        start_poses.append(
            {"name": names[i], "x": round(float(px[r, c]), 3), "y": round(float(py[r, c]), 3), "yaw": yaw}
        )
    floor = floor_spec(rng, leaves, names)
    return {
        "name": f"random:{seed}",
        "wall_thickness": WALL_T,
        "ceiling_color": ceiling_color(rng),
        "door_texture": "door_jamb",
        "floor": floor,
        "lighting": lighting_spec(rng, w, h),
        "textures": textures,
        "rooms": rooms,
        "walls": walls,
        "furniture": furniture,
        "start_poses": start_poses,
    }
