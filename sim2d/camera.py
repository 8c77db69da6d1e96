"""Forward-looking perspective camera rendered by raycasting the 2D house, fully numpy-vectorised.

One frame is:

1. one ray per image column against every front-facing surface segment (one small matmul gives every
   ray/segment cross product at once), keeping two layers per column: the nearest wall and the nearest
   furniture in front of it (furniture is lower than walls, so the wall shows above it);
2. per pixel, the height z where the pixel's ray meets each layer's depth decides what it sees: furniture,
   else wall, else floor (below) or ceiling (above);
3. a single gather from one packed texture atlas (uint32 RGBA) that holds every surface texture with its
   mip levels, the floor mosaic with its mip levels and the ceiling colour; the mip level of a floor pixel
   depends only on its row, of a surface only on its column's depth, so anti-aliasing costs no extra pass;
4. distance shading (precomputed per row for floor and ceiling, per column for surfaces) times brightness.

Everything that does not depend on the pose (ray directions in the camera frame, per-row ground depth,
mip levels and shading of floor rows, the atlas) is computed once in the constructor.
"""

from __future__ import annotations

import math

import numpy as np

from sim2d.config import CameraConfig
from sim2d.house import House
from sim2d.textures import TEX, mip_levels

_TEX_LEVELS = 4  # mip levels kept per surface texture: 64, 32, 16, 8 texels
_FLOOR_LEVELS = 7  # 512 .. 8 texels
_NO_HIT = 1e6  # depth used for "nothing hit" (finite, so that no inf/nan warnings arise)


def _pack(img: np.ndarray) -> np.ndarray:
    """(..., 3) uint8 RGB -> (...) uint32 whose little-endian bytes are R, G, B, 255."""
    rgba = np.concatenate([img, np.full(img.shape[:-1] + (1,), 255, np.uint8)], axis=-1)
    return np.ascontiguousarray(rgba).view("<u4")[..., 0]


class Camera:
    """Renders (H, W, 3) uint8 RGB images of a House from planar poses."""

    def __init__(self, house: House, cfg: CameraConfig) -> None:
        self.house = house
        self.cfg = cfg
        ss = cfg.supersample
        self.rw, self.rh = cfg.width * ss, cfg.height * ss
        f = cfg.focal_px * ss
        self.focal = f
        too_low = [fu.name for fu in house.furniture if fu.height <= cfg.camera_height]
        if too_low:
            # The renderer draws vertical faces only; a top face seen from above would be missing.
            raise ValueError(
                f"CameraConfig.camera_height ({cfg.camera_height} m) must be below every furniture height; "
                f"lower than it: {', '.join(too_low)}"
            )

        # ---- rays: column c looks along (1, -xc) in the camera frame (x forward, y left)
        self.xc = ((np.arange(self.rw) + 0.5 - self.rw / 2) / f).astype(np.float64)  # (W,)
        self.yr = ((np.arange(self.rh) + 0.5 - self.rh / 2) / f).astype(np.float32)  # (H,) +down
        self._yr_col = self.yr[:, None]  # (H, 1)

        # ---- segments, walls first
        seg = house.segments
        order = np.argsort(~seg.is_wall, kind="stable")
        self.seg_a = seg.a[order]
        e = seg.b[order] - seg.a[order]
        self.seg_e = e
        self.seg_len = np.hypot(e[:, 0], e[:, 1])
        self.seg_u0 = seg.u0[order]
        self.seg_tex = seg.texture[order]
        self.seg_height = np.where(seg.is_wall[order], cfg.wall_height, seg.height[order])
        self.n_walls = int(seg.is_wall.sum())

        # ---- atlas: [surface textures x mip levels] + [floor mip levels] + [ceiling, far]
        chunks: list[np.ndarray] = []
        offset = 0
        n_tex = len(house.texture_images)
        self.tex_offset = np.zeros((n_tex, _TEX_LEVELS), dtype=np.int64)
        for t, img in enumerate(house.texture_images):
            for lvl, m in enumerate(mip_levels(img, _TEX_LEVELS)):
                self.tex_offset[t, lvl] = offset
                chunks.append(_pack(m).ravel())
                offset += m.shape[0] * m.shape[1]
        floor_offsets = []
        floor_sizes = []
        for m in mip_levels(house.floor_image, _FLOOR_LEVELS):
            floor_offsets.append(offset)
            floor_sizes.append(m.shape[0])
            chunks.append(_pack(m).ravel())
            offset += m.shape[0] * m.shape[1]
        self.ceiling_index = offset
        self.far_index = offset + 1
        ceiling = house.ceiling_color.astype(np.uint8)
        chunks.append(_pack(np.stack([ceiling, np.array([20, 20, 25], np.uint8)])))
        self.atlas = np.concatenate(chunks)  # (N,) uint32
        self.tex_size_u = house.texture_sizes[:, 0]
        self.tex_size_v = house.texture_sizes[:, 1]

        # ---- floor rows (below the horizon): ground depth, mip level, shading
        below = self.yr > 0
        self.floor_row0 = int(np.argmax(below)) if below.any() else self.rh
        yr_b = self.yr[self.floor_row0 :].astype(np.float64)
        g = cfg.camera_height / yr_b  # (Hb,) forward depth of the floor seen by each row
        res0 = house.floor_extent / floor_sizes[0]
        # Footprint of one pixel on the floor: g/f across, g^2/(f*h) along the view; take the geometric mean.
        foot = np.sqrt((g / f) * (g * g / (f * cfg.camera_height)))
        level = np.clip(np.round(np.log2(np.maximum(foot / res0, 1e-9))), 0, len(floor_sizes) - 1).astype(int)
        n_row = np.asarray(floor_sizes)[level].astype(np.int64)
        inv_cell = n_row / house.floor_extent  # texels per metre at each row's level
        self._floor_g = g
        self._floor_inv = inv_cell
        self._floor_gi = (g * inv_cell)[:, None].astype(np.float32)  # (Hb, 1)
        self._floor_mask = (n_row - 1)[:, None].astype(np.int32)
        self._floor_n = n_row[:, None].astype(np.int32)
        self._floor_off = np.asarray(floor_offsets, dtype=np.int64)[level][:, None].astype(np.int32)
        self._floor_far = (g > cfg.max_range)[:, None]
        self._floor_origin = house.floor_origin

        # ---- background (ceiling above the horizon) and per-row shading of floor and ceiling
        depth_rows = np.full(self.rh, _NO_HIT)
        with np.errstate(divide="ignore"):
            up = self.yr < 0
            depth_rows[up] = (cfg.wall_height - cfg.camera_height) / (-self.yr[up].astype(np.float64))
        depth_rows[self.floor_row0 :] = g
        self._row_shade = self._shade(depth_rows).astype(np.float32)[:, None]  # (H, 1)
        self._ceiling_rows = np.full((self.floor_row0, self.rw), self.ceiling_index, dtype=np.int32)

        if self.atlas.size >= 2**31:
            raise ValueError("texture atlas too large for int32 indices")

    def _shade(self, depth: np.ndarray) -> np.ndarray:
        c = self.cfg
        return c.ambient + (1.0 - c.ambient) * np.exp(-np.asarray(depth) / c.shading_distance)

    # ------------------------------------------------------------------------------------------------
    def raycast(self, x: float, y: float, yaw: float) -> dict[str, np.ndarray]:
        """Per column: depth (forward distance), segment index and position along it, for both layers."""
        cos, sin = math.cos(yaw), math.sin(yaw)
        dx = cos + sin * self.xc  # (W,) world ray directions, forward component 1
        dy = sin - cos * self.xc
        ap = self.seg_a - np.array([x, y])  # (S, 2)
        e = self.seg_e
        t_num = ap[:, 0] * e[:, 1] - ap[:, 1] * e[:, 0]  # (S,) < 0 where the camera sees the front face
        front = np.flatnonzero(t_num < 0)
        n_w = int(np.searchsorted(front, self.n_walls))  # front faces that are walls come first
        ef, apf = e[front], ap[front]
        m = np.empty((2, 2 * len(front)))
        m[0, : len(front)] = ef[:, 1]
        m[1, : len(front)] = -ef[:, 0]
        m[0, len(front) :] = -apf[:, 1]
        m[1, len(front) :] = apf[:, 0]
        r = np.stack([dx, dy], axis=1) @ m  # (W, 2S'): [denom | s_num]
        denom = r[:, : len(front)]
        s_num = r[:, len(front) :]
        # A front face is hit iff the ray points at it (denom < 0) within the segment (0 <= s <= 1).
        # Then depth t = t_num / denom > 0; we maximise 1/t = denom / t_num to avoid a division per pair.
        valid = (denom < 0) & (s_num <= 0) & (s_num >= denom)
        inv_t = np.where(valid, denom * (1.0 / t_num[front]), 0.0)  # (W, S')
        cols = np.arange(self.rw)
        out = {}
        for name, lo, hi in (("wall", 0, n_w), ("furn", n_w, len(front))):
            if hi <= lo:
                out[name + "_depth"] = np.full(self.rw, _NO_HIT)
                out[name + "_seg"] = np.zeros(self.rw, dtype=np.int64)
                out[name + "_s"] = np.zeros(self.rw)
                continue
            k = np.argmax(inv_t[:, lo:hi], axis=1) + lo  # (W,)
            best = inv_t[cols, k]
            hit = best > 1.0 / self.cfg.max_range
            depth = np.where(hit, 1.0 / np.where(hit, best, 1.0), _NO_HIT)
            s = np.where(hit, s_num[cols, k] / np.where(hit, denom[cols, k], -1.0), 0.0)
            out[name + "_depth"] = depth
            out[name + "_seg"] = front[k]
            out[name + "_s"] = s
        out["dx"], out["dy"] = dx, dy
        return out

    def _layer(self, depth: np.ndarray, seg: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, ...]:
        """Per-column atlas base index, v scale, v mask and shift, and height of one layer."""
        tex = self.seg_tex[seg]
        u = self.seg_u0[seg] + s * self.seg_len[seg]  # (W,) metres along the surface
        # Mip level from the pixel footprint (depth / f metres) over the texel size at level 0.
        texel = np.minimum(self.tex_size_u[tex], self.tex_size_v[tex]) / TEX
        lvl = np.clip(np.floor(np.log2(np.maximum(depth / self.focal / texel, 1e-9))), 0, _TEX_LEVELS - 1)
        lvl = lvl.astype(np.int64)
        n = TEX >> lvl  # texels per side at that level
        upix = (u * (n / self.tex_size_u[tex])).astype(np.int64) & (n - 1)
        base = self.tex_offset[tex, lvl] + upix
        vscale = (n / self.tex_size_v[tex]).astype(np.float32)
        shift = (TEX.bit_length() - 1 - lvl).astype(np.int32)
        return (
            base.astype(np.int32),
            vscale,
            (n - 1).astype(np.int32),
            shift,
            self.seg_height[seg].astype(np.float32),
        )

    def render(self, x: float, y: float, yaw: float) -> np.ndarray:
        """The (height, width, 3) uint8 RGB image seen from pose (x, y, yaw)."""
        cfg = self.cfg
        rc = self.raycast(x, y, yaw)
        dw = rc["wall_depth"]
        df = rc["furn_depth"]
        df = np.where(df < dw, df, _NO_HIT)
        yr = self._yr_col

        # ---- background: ceiling above the horizon, mosaic floor below
        ox, oy = self._floor_origin
        fx = (x - ox) * self._floor_inv[:, None] + self._floor_gi * rc["dx"].astype(np.float32)  # (Hb, W)
        fy = (y - oy) * self._floor_inv[:, None] + self._floor_gi * rc["dy"].astype(np.float32)
        ix = fx.astype(np.int32) & self._floor_mask
        iy = fy.astype(np.int32) & self._floor_mask
        floor_idx = self._floor_off + iy * self._floor_n + ix
        floor_idx = np.where(self._floor_far, self.far_index, floor_idx)
        idx = np.concatenate([self._ceiling_rows, floor_idx], axis=0)  # (H, W)
        shade = np.broadcast_to(self._row_shade, idx.shape)

        # ---- walls, then furniture on top
        for depth, seg, s in ((dw, rc["wall_seg"], rc["wall_s"]), (df, rc["furn_seg"], rc["furn_s"])):
            base, vscale, vmask, shift, height = self._layer(depth, seg, s)
            z = cfg.camera_height - yr * depth.astype(np.float32)  # (H, W) height seen on this layer
            vis = (z >= 0) & (z < height)
            vpix = (z * vscale).astype(np.int32) & vmask
            idx = np.where(vis, base + (vpix << shift), idx)
            shade = np.where(vis, self._shade(depth).astype(np.float32), shade)

        rgb = self.atlas[idx].view(np.uint8).reshape(self.rh, self.rw, 4)[..., :3]
        light = shade * np.float32(cfg.brightness)
        img = rgb * light[..., None]
        np.clip(img, 0, 255, out=img)
        if cfg.supersample > 1:
            ss = cfg.supersample
            img = img.reshape(cfg.height, ss, cfg.width, ss, 3).mean(axis=(1, 3))
            return np.rint(img).astype(np.uint8)
        return img.astype(np.uint8)
