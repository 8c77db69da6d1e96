"""Floor images: one house-sized RGB image painted from a base kind and polygonal regions (numpy only).

A map's ``floor`` object holds the base floor and optional regions painted over it, in order::

    "floor": {"tile": 0.3, "seed": 7, "grout": [55, 55, 60],        # the base (mosaic unless "kind")
              "kind": "mosaic" | "planks" | "tiles" | "plain",     # optional, default "mosaic"
              "colors": [[r, g, b], ...],                          # planks / tiles / plain / rug colours
              "regions": [{"polygon": [[x, y], ...], "kind": ..., "seed": int, "tile": m,
                           "grout": [r, g, b], "colors": [...], "vertical": bool}, ...]}

Kinds: ``mosaic`` (irregular coloured tiles, the paper's floor), ``planks`` (boards ``tile`` wide with
staggered joints, per-board tone and grain), ``tiles`` (square ``tile`` tiles with grout, a checker when
two colours are given), ``plain`` (one colour with faint mottling, like lino or concrete) and ``rug``
(a border band around a striped field, for rugs and mats: things lower than the camera seen from above).
Regions give rooms their own floor, lay rugs, or re-colour part of the floor (sim2d.appearance).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from vtr.sim2d.textures import mosaic_floor

FLOOR_KINDS = ("mosaic", "planks", "tiles", "plain", "rug")
_DEFAULT_COLORS = {
    "planks": [[150, 105, 65], [120, 80, 45]],
    "tiles": [[210, 205, 195]],
    "plain": [[150, 150, 145]],
    "rug": [[150, 40, 50], [220, 190, 120]],
    "mosaic": [[128, 128, 128]],
}


def _colors(spec: dict[str, Any], kind: str, where: str) -> np.ndarray:
    cols = spec.get("colors", _DEFAULT_COLORS[kind])
    ok = (
        isinstance(cols, list)
        and cols
        and all(
            isinstance(c, list)
            and len(c) == 3
            and all(isinstance(v, (int, float)) and 0 <= v <= 255 for v in c)
            for c in cols
        )
    )
    if not ok:
        raise ValueError(f"{where}.colors: expected a non-empty list of [r, g, b] in 0..255, got {cols!r}")
    return np.asarray(cols, dtype=np.float32)


def _hash01(i: np.ndarray, j: np.ndarray, seed: int) -> np.ndarray:
    """A deterministic pseudo-random value in [0, 1) per integer cell (i, j)."""
    h = (i.astype(np.int64) * 73856093) ^ (j.astype(np.int64) * 19349663) ^ (seed * 83492791)
    h = (h ^ (h >> 13)) * 1274126177
    return ((h ^ (h >> 16)) & 0xFFFF).astype(np.float32) / 65536.0


def _paint(
    kind: str, spec: dict[str, Any], px: np.ndarray, py: np.ndarray, where: str, grid: tuple
) -> np.ndarray:
    """(n, n, 3) float32 colours of `kind` at world points (px, py)."""
    seed = int(spec.get("seed", 0))
    tile = float(spec.get("tile", 0.3))
    if not 0.02 <= tile <= 5.0:
        raise ValueError(f"{where}.tile: expected metres in [0.02, 5], got {tile!r}")
    grout = np.asarray(spec.get("grout", [60, 60, 60]), dtype=np.float32)
    cols = _colors(spec, kind, where)
    if kind == "mosaic":
        x0, y0, extent, n = grid
        return mosaic_floor(x0, y0, extent, n, tile, seed, grout).astype(np.float32)
    along, across = (py, px) if spec.get("vertical", False) else (px, py)
    if kind == "planks":
        row = np.floor(across / tile)
        board_len = 6.0 * tile
        offset = _hash01(row, row * 0 + 1, seed) * board_len
        col = np.floor((along + offset) / board_len)
        tone = _hash01(row, col, seed)
        base = cols[(row.astype(np.int64) + col.astype(np.int64)) % len(cols)]
        grain = 0.92 + 0.08 * np.sin(2 * np.pi * (across / tile * 3.0 + 0.3 * np.sin(along * 4.0 + tone * 9)))
        img = base * ((0.85 + 0.3 * tone) * grain)[..., None]
        seam = ((across / tile) % 1.0 < 0.04) | (((along + offset) / board_len) % 1.0 < 0.008)
        return np.where(seam[..., None], img * 0.55, img)
    if kind == "tiles":
        i, j = np.floor(px / tile), np.floor(py / tile)
        base = cols[((i + j).astype(np.int64)) % len(cols)]
        img = base * (0.94 + 0.12 * _hash01(i, j, seed))[..., None]
        g = 0.05
        border = ((px / tile) % 1.0 < g) | ((py / tile) % 1.0 < g)
        return np.where(border[..., None], grout, img)
    if kind == "plain":
        # Faint low-frequency mottling (sum of two coarse value-noise grids), as on lino or concrete.
        m = 0.0
        for scale, amp in ((0.7, 0.04), (0.15, 0.02)):
            m = m + amp * (_hash01(np.floor(px / scale), np.floor(py / scale), seed) - 0.5)
        return cols[0] * (1.0 + m)[..., None]
    if kind == "rug":
        x0, x1 = float(spec["_box"][0]), float(spec["_box"][2])
        y0, y1 = float(spec["_box"][1]), float(spec["_box"][3])
        edge = np.minimum.reduce([px - x0, x1 - px, py - y0, y1 - py])
        band = 0.08 + 0.04 * (seed % 3)
        field = cols[1 % len(cols)] if len(cols) > 1 else cols[0] * 0.7
        stripe = np.floor(along / max(tile / 3.0, 0.04)) % 2
        img = np.where(stripe[..., None] > 0, field, field * 0.8)
        return np.where((edge < band)[..., None], cols[0], img)
    raise ValueError(f"{where}.kind: expected one of {', '.join(FLOOR_KINDS)}, got {kind!r}")


def _inside_mask(poly: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test for every grid point."""
    inside = np.zeros(px.shape, dtype=bool)
    for k in range(len(poly)):
        (ax, ay), (bx, by) = poly[k], poly[(k + 1) % len(poly)]
        if ay == by:
            continue
        cross = (ay > py) != (by > py)
        xint = ax + (py - ay) * (bx - ax) / (by - ay)
        inside ^= cross & (px < xint)
    return inside


def floor_image(
    spec: dict[str, Any], origin: tuple[float, float], extent: float, n: int, where: str
) -> np.ndarray:
    """The (n, n, 3) uint8 floor over [x0, x0 + extent] x [y0, y0 + extent]; row = y, column = x."""
    x0, y0 = origin
    c = (np.arange(n) + 0.5) * extent / n
    px, py = np.meshgrid(x0 + c, y0 + c, indexing="xy")
    grid = (x0, y0, extent, n)
    kind = spec.get("kind", "mosaic")
    if kind == "rug":
        raise ValueError(f"{where}.kind: 'rug' is for regions only")
    img = _paint(kind, spec, px, py, where, grid)
    regions = spec.get("regions", [])
    if not isinstance(regions, list):
        raise ValueError(f"{where}.regions: expected a list, got {regions!r}")
    for i, r in enumerate(regions):
        w = f"{where}.regions[{i}]"
        if not isinstance(r, dict):
            raise ValueError(f"{w}: expected an object, got {r!r}")
        poly = r.get("polygon")
        if not isinstance(poly, list) or len(poly) < 3:
            raise ValueError(f"{w}.polygon: expected at least 3 [x, y] points, got {poly!r}")
        try:
            poly_a = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
        except (TypeError, ValueError):
            raise ValueError(f"{w}.polygon: expected [x, y] points, got {poly!r}") from None
        lo, hi = poly_a.min(axis=0), poly_a.max(axis=0)
        # Paint only the grid's bounding box of the region (regions are small beside the house).
        i0, j0 = np.clip(np.floor((lo - (x0, y0)) / extent * n).astype(int), 0, n)
        i1, j1 = np.clip(np.ceil((hi - (x0, y0)) / extent * n).astype(int) + 1, 0, n)
        if i1 <= i0 or j1 <= j0:
            continue
        sub = (slice(j0, j1), slice(i0, i1))
        mask = _inside_mask(poly_a, px[sub], py[sub])
        rkind = r.get("kind", "plain")
        rspec = dict(r, _box=[lo[0], lo[1], hi[0], hi[1]])
        if rkind == "mosaic":  # the mosaic painter works on the whole grid
            paint = _paint(rkind, rspec, px, py, w, grid)[sub]
        else:
            paint = _paint(rkind, rspec, px[sub], py[sub], w, grid)
        img[sub] = np.where(mask[..., None], paint, img[sub])
    return np.clip(img, 0, 255).astype(np.uint8)
