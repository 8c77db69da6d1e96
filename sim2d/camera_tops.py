"""Furniture seen from above (sim2d.camera's 2.5D part): the tops of pieces lower than the camera.

A column's ray enters a convex piece through a front face at forward depth t_in and leaves it through a
back face at t_out. For a piece of height h below the camera (h_cam > h), a pixel row of ray slope yr > 0
meets the plane z = h at depth (h_cam - h) / yr, so it sees the top where t_in <= (h_cam - h) / yr < t_out:
the rows just above the piece's front face (which covers z in [0, h) at t_in). Rows above those look past
the piece, at what lies behind it: the wall, the floor beyond the piece's shadow, or the next piece, which
is why a camera above some furniture keeps a second furniture layer per column (drawn first, painter's
order). A third piece in the same column behind those two is not drawn (the layer limit).

A top is one colour per piece (its texture's mean, lit by the house light at its centre and a little
brighter than the sides, as horizontal surfaces under ceiling lights are), shaded by distance like every
surface: per (piece, pixel row) one atlas item, so a top costs one table lookup per pixel.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from vtr.sim2d.rays import inverse_depths

if TYPE_CHECKING:
    from vtr.sim2d.camera import Camera
    from vtr.sim2d.house import House

#: Tops are lit from above: this much brighter than the piece's texture.
TOP_LIGHT = 1.1
_NO_HIT = 1e6  # sim2d.camera's depth for "nothing hit"


def top_tables(
    cam: Camera, house: House, centres: np.ndarray, bin_light: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(atlas item of each piece's top at each pixel row (P, rows) int32, camera height above each top (P,)
    float32, <= 0 for a piece the camera does not look down on). Adds the tops' colours to the atlas."""
    heights = np.array([fu.height for fu in house.furniture], dtype=np.float64)
    dh = cam.cfg.camera_height - heights
    tab = np.zeros((len(heights), cam.rh), dtype=np.int32)
    if not len(heights):
        return tab, dh.astype(np.float32)
    light = house.lighting.face_levels(np.array([fu.center for fu in house.furniture], dtype=np.float64))
    slope = np.maximum(cam.yr, 1e-9)  # rows at or above the horizon never see a top
    for i, fu in enumerate(house.furniture):
        if dh[i] <= 0:
            continue
        image = house.texture_images[house.texture_names.index(fu.texture)]
        colour = image.reshape(-1, 3).astype(np.float32).mean(axis=0) * TOP_LIGHT
        offsets = cam._add(colour[None, :], bin_light * light[i])  # one item per depth bin
        tab[i] = offsets[np.searchsorted(cam._bin_edges, dh[i] / slope)]
    return tab, dh.astype(np.float32)


def far_sides(
    cam: Camera,
    dirs: np.ndarray,
    ap: np.ndarray,
    t_num: np.ndarray,
    beyond: np.ndarray,
    seg: np.ndarray,
    depth: np.ndarray,
) -> np.ndarray:
    """(layers, W) forward depth t_out where each column's ray leaves the piece of its furniture layers (the
    layer's own depth where it hits nothing, or for walls). Back faces are front faces of the reversed
    segment (start b, direction -e), so sim2d.rays finds them; only pieces lower than the camera count."""
    t_out = depth.copy()
    low = cam._top_dh[np.maximum(cam._seg_piece, 0)] > 0
    back = np.flatnonzero((t_num > 0) & ~beyond & low & (cam._seg_piece >= 0))
    if back.size == 0:
        return t_out
    inv_back, _, _ = inverse_depths(
        dirs, -cam._surfaces.e_perp_t[:, back], ap[back] + cam.seg_e[back], -t_num[back]
    )
    back_piece = cam._seg_piece[back]
    for layer in range(1, depth.shape[0]):
        piece = cam._seg_piece[seg[layer]]
        inv = np.where(back_piece[None, :] == piece[:, None], inv_back, 0.0).max(axis=1)
        ok = (inv > 0) & (depth[layer] < _NO_HIT)
        t_out[layer] = np.where(ok, 1.0 / np.where(ok, inv, 1.0), depth[layer])
    return t_out


def draw_tops(cam: Camera, idx: np.ndarray, rc: dict[str, np.ndarray], layer: int, cs: slice) -> None:
    """Write the atlas items of the tops furniture ``layer`` shows in columns ``cs`` into ``idx``."""
    t_in = rc["depth"][layer, cs]
    piece = cam._seg_piece[rc["seg"][layer, cs]]
    dh = np.where((t_in < _NO_HIT) & (piece >= 0), cam._top_dh[np.maximum(piece, 0)], 0.0)
    if not np.any(dh > 0):
        return
    t_out = rc["t_out"][layer, cs]
    centre, f = cam.rh / 2 - 0.5, cam.focal
    seen = dh > 0
    r0 = max(cam.floor_row0, int(np.floor(centre + f * float(np.min(dh[seen] / t_out[seen])))) - 1)
    r1 = min(cam.rh, int(np.ceil(centre + f * float(np.max(dh[seen] / t_in[seen])))) + 2)
    if r1 <= r0:
        return
    yr = cam.yr_col[r0:r1]  # (h, 1)
    dh32 = dh.astype(np.float32)
    vis = yr * t_out.astype(np.float32) >= dh32
    vis &= yr * t_in.astype(np.float32) < dh32
    vis &= seen
    items = cam._top_tab[np.maximum(piece, 0)[None, :], np.arange(r0, r1)[:, None]]
    np.putmask(idx[r0:r1, cs], vis, items)
