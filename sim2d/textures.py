"""Procedural textures (numpy only), generated once when a house loads.

Every surface texture is a square TEX x TEX RGB uint8 array that repeats every `size` = (su, sv) metres
along the surface (u) and up its height (v); row 0 is at the floor. The floor is one house-sized
mosaic of irregular coloured tiles (a jittered-grid Voronoi diagram with dark grout), like the mosaic the
paper laid in its Gazebo house so that images are rich in features.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

TEX = 64  # texels per side of a surface texture (power of two: the renderer wraps with a bit mask)

KINDS = ("solid", "stripes", "bricks", "checker", "gradient", "wood", "diamonds", "dots", "tiles", "poster")


def _rgb(value: Any, where: str) -> np.ndarray:
    if (
        not isinstance(value, (list, tuple))
        or len(value) != 3
        or not all(isinstance(c, (int, float)) and 0 <= c <= 255 for c in value)
    ):
        raise ValueError(f"{where}: expected an [r, g, b] colour with values in 0..255, got {value!r}")
    return np.asarray(value, dtype=np.float32)


def _grain(seed: int, amount: float) -> np.ndarray:
    """Small deterministic per-texel brightness jitter so flat areas still carry some texture."""
    rng = np.random.default_rng(seed)
    return 1.0 + amount * rng.standard_normal((TEX, TEX, 1)).astype(np.float32)


def make_texture(spec: Mapping[str, Any], where: str, seed: int) -> np.ndarray:
    """Build one (TEX, TEX, 3) uint8 texture from its JSON spec; `where` names it in error messages."""
    kind = spec.get("kind")
    if kind not in KINDS:
        raise ValueError(f"{where}.kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    colors = spec.get("colors")
    if not isinstance(colors, list) or not colors:
        raise ValueError(f"{where}.colors: expected a non-empty list of [r, g, b], got {colors!r}")
    cols = [_rgb(c, f"{where}.colors[{i}]") for i, c in enumerate(colors)]
    a = cols[0]
    b = cols[1] if len(cols) > 1 else a * 0.6
    count = spec.get("count", 4)
    if not isinstance(count, int) or isinstance(count, bool) or not 1 <= count <= TEX // 2:
        raise ValueError(f"{where}.count: expected an integer in 1..{TEX // 2}, got {count!r}")
    vertical = bool(spec.get("vertical", True))
    v, u = np.mgrid[0:TEX, 0:TEX].astype(np.float32) / TEX  # (TEX, TEX) each, in [0, 1)
    if kind == "solid":
        t = np.zeros_like(u)
    elif kind == "stripes":
        t = (np.floor((u if vertical else v) * count) % 2).astype(np.float32)
    elif kind == "checker":
        t = ((np.floor(u * count) + np.floor(v * count)) % 2).astype(np.float32)
    elif kind == "gradient":
        t = u if vertical else v
        t = 0.5 - 0.5 * np.cos(2 * np.pi * t)  # periodic so that repeats do not show a seam
    elif kind == "bricks":
        rows = count * 2
        row = np.floor(v * rows)
        shifted = u * count + 0.5 * (row % 2)
        mortar_u = (shifted - np.floor(shifted)) < 0.08
        mortar_v = (v * rows - row) < 0.12
        t = (mortar_u | mortar_v).astype(np.float32)
    elif kind == "wood":
        x = u if vertical else v
        y = v if vertical else u
        t = 0.5 + 0.5 * np.sin(2 * np.pi * (count * x + 0.15 * np.sin(2 * np.pi * 2 * y)))
    elif kind == "diamonds":
        t = ((np.abs((u * count) % 1 - 0.5) + np.abs((v * count) % 1 - 0.5)) < 0.35).astype(np.float32)
    elif kind == "tiles":  # square tiles (colour a) with thin grout lines (colour b)
        t = (((u * count) % 1 < 0.06) | ((v * count) % 1 < 0.06)).astype(np.float32)
    elif kind == "poster":  # a framed picture of count x count coloured blocks on a plain wall (colour a)
        inside = (u >= 0.3) & (u < 0.7) & (v >= 0.5) & (v < 0.85)
        frame = (u >= 0.28) & (u < 0.72) & (v >= 0.48) & (v < 0.87) & ~inside
        rng = np.random.default_rng(seed)
        palette = np.stack(cols[1:] if len(cols) > 1 else [b, a * 0.3 + 100])
        blocks = rng.integers(0, len(palette), size=(count, count))
        bi = np.clip(((u - 0.3) / 0.4 * count).astype(int), 0, count - 1)
        bj = np.clip(((v - 0.5) / 0.35 * count).astype(int), 0, count - 1)
        img = np.where(inside[..., None], palette[blocks[bj, bi]], a)
        img = np.where(frame[..., None], np.float32(40.0), img) * _grain(seed, float(spec.get("grain", 0.01)))
        return np.clip(img, 0, 255).astype(np.uint8)
    else:  # dots
        t = ((((u * count) % 1 - 0.5) ** 2 + ((v * count) % 1 - 0.5) ** 2) < 0.09).astype(np.float32)
    img = a * (1.0 - t[..., None]) + b * t[..., None]
    if len(cols) > 2:  # a third colour tints every other repeat cell for extra variety
        cell = (np.floor(u * 2) + np.floor(v * 2)) % 2
        img = np.where(cell[..., None] > 0, 0.75 * img + 0.25 * cols[2], img)
    img = img * _grain(seed, float(spec.get("grain", 0.04)))
    return np.clip(img, 0, 255).astype(np.uint8)


def mosaic_floor(
    x0: float, y0: float, extent: float, n: int, tile: float, seed: int, grout: np.ndarray
) -> np.ndarray:
    """A (n, n, 3) uint8 mosaic covering [x0, x0 + extent] x [y0, y0 + extent]; row = y, column = x.

    Tiles are the Voronoi cells of one jittered seed per `tile`-sized grid cell; the nearest seed is
    searched among the 3x3 neighbouring cells only, which is exact for jitter < half a cell.
    """
    rng = np.random.default_rng(seed)
    cells = int(np.ceil(extent / tile)) + 2
    jitter = rng.uniform(0.1, 0.9, size=(cells, cells, 2))
    seeds = (
        np.stack(np.meshgrid(np.arange(cells), np.arange(cells), indexing="xy"), axis=-1) + jitter
    ) * tile
    # Saturated colours at varied brightness: hue anywhere, saturation and value high.
    hue = rng.uniform(0, 1, size=(cells, cells))
    sat = rng.uniform(0.45, 0.95, size=(cells, cells))
    val = rng.uniform(0.45, 1.0, size=(cells, cells))
    colors = _hsv_to_rgb(hue, sat, val) * 255.0  # (cells, cells, 3)

    res = extent / n
    coords = (np.arange(n) + 0.5) * res + tile  # shift by one cell so neighbours of the first cell exist
    px, py = np.meshgrid(coords, coords, indexing="xy")  # (n, n)
    cx = np.floor(px / tile).astype(np.int64)
    cy = np.floor(py / tile).astype(np.int64)
    best = np.full((n, n), np.inf)
    second = np.full((n, n), np.inf)
    best_col = np.zeros((n, n, 3))
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            ix = np.clip(cx + dx, 0, cells - 1)
            iy = np.clip(cy + dy, 0, cells - 1)
            s = seeds[iy, ix]  # (n, n, 2): seeds[row=y cell, col=x cell] holds (x, y)
            d = np.hypot(s[..., 0] - px, s[..., 1] - py)
            closer = d < best
            second = np.where(closer, best, np.minimum(second, d))
            best = np.where(closer, d, best)
            best_col = np.where(closer[..., None], colors[iy, ix], best_col)
    # Grout where the two nearest seeds are almost equidistant (the cell border).
    border = (second - best) < 0.08 * tile
    img = np.where(border[..., None], grout[None, None, :], best_col)
    return np.clip(img, 0, 255).astype(np.uint8)


def _hsv_to_rgb(h: np.ndarray, s: np.ndarray, v: np.ndarray) -> np.ndarray:
    i = np.floor(h * 6.0).astype(np.int64) % 6
    f = h * 6.0 - np.floor(h * 6.0)
    p = v * (1 - s)
    q = v * (1 - f * s)
    t = v * (1 - (1 - f) * s)
    table = np.stack(
        [
            np.stack([v, t, p], -1),
            np.stack([q, v, p], -1),
            np.stack([p, v, t], -1),
            np.stack([p, q, v], -1),
            np.stack([t, p, v], -1),
            np.stack([v, p, q], -1),
        ],
        axis=0,
    )  # (6, ..., 3)
    return np.take_along_axis(table, i[None, ..., None].repeat(3, axis=-1), axis=0)[0]


def mip_levels(img: np.ndarray, levels: int) -> list[np.ndarray]:
    """Box-filtered mip pyramid of a square power-of-two texture: [full, half, quarter, ...]."""
    out = [img]
    cur = img.astype(np.float32)
    for _ in range(levels - 1):
        h, w = cur.shape[:2]
        if h < 2 or w < 2:
            break
        cur = cur.reshape(h // 2, 2, w // 2, 2, 3).mean(axis=(1, 3))
        out.append(np.clip(np.rint(cur), 0, 255).astype(np.uint8))
    return out
