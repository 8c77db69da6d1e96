"""Forward-looking perspective camera rendered by raycasting the 2D house, fully numpy-vectorised.

One frame is:

1. one ray per image column against the surface segments that face the camera and overlap the field of
   view (one small matmul gives every ray/segment cross product at once: sim2d.rays, which the
   rangefinder shares), keeping two layers per column:
   the nearest wall and the nearest furniture in front of it (furniture is lower than walls, so the wall
   shows above it; furniture hidden behind other furniture is not drawn, a limit of two layers). A camera
   above some furniture keeps a third layer, the second nearest piece, and draws the tops of pieces lower
   than itself (sim2d.camera_tops, a 2.5D raycaster's floor-and-top rule);
2. per column and layer, one lookup in a (segment, depth bin) table gives the texture block to read
   (mip level and distance shading of that bin), the texture column, and the texture row as a linear
   function of the pixel's ray slope, v = a - yr * b; per pixel, 0 <= v < v_top says whether the pixel
   sees that layer. Pixels that see no layer see the floor (below the horizon) or the ceiling (above).
   Per-pixel work is limited to the bounding box of rows and columns where each layer can appear;
3. the floor point a pixel sees is the camera position plus the row's ground depth times the column's
   ray direction; the row also fixes the floor's mip level and shading, so the mosaic is anti-aliased and
   shaded at no per-pixel cost;
4. a single gather from one atlas of 3-byte RGB items that holds every texel already shaded and scaled
   by the brightness: surface textures for each depth bin (64 bins from 0.1 m to max range, ratio ~1.09,
   so shading steps stay under 2%), floor mip levels for each shading the floor rows use, one ceiling
   colour per row, and the far colour. No arithmetic on colours is left per frame.

Everything that does not depend on the pose (ray directions in the camera frame, per-row ground depth,
mip levels and shading, the atlas) is computed once in the constructor (~0.2 s, ~23 MB for the default
house at 128x128).
"""

from __future__ import annotations

import math

import numpy as np

from vtr.sim2d.camera_tops import draw_tops, far_sides, top_tables
from vtr.sim2d.config import CameraConfig
from vtr.sim2d.house import House
from vtr.sim2d.rays import Surfaces, inverse_depths
from vtr.sim2d.textures import TEX, mip_levels

_TEX_LEVELS = 4  # mip levels kept per surface texture: 64, 32, 16, 8 texels
_TEX_SHIFT = TEX.bit_length() - 1  # log2(TEX)
_FLOOR_LEVELS = 7  # 512 .. 8 texels
_DEPTH_BINS = 64  # surfaces: distance bins from 0.1 m to max range (ratio ~1.09: shading steps < 2%)
_NO_HIT = 1e6  # depth used for "nothing hit" (finite, so that no inf/nan warnings arise)


class Camera:
    """Renders (H, W, 3) uint8 RGB images of a House from planar poses."""

    def __init__(self, house: House, cfg: CameraConfig) -> None:
        self.house = house
        self.cfg = cfg
        ss = cfg.supersample
        self.rw, self.rh = cfg.width * ss, cfg.height * ss
        f = cfg.focal_px * ss
        self.focal = f
        # Furniture whose top the camera looks down on: then two furniture layers per column, and tops.
        self.tops = any(fu.height < cfg.camera_height - 1e-6 for fu in house.furniture)

        # ---- rays: column c looks along (1, -xc) in the camera frame (x forward, y left)
        self.xc = (np.arange(self.rw) + 0.5 - self.rw / 2) / f  # (W,)
        yr = (np.arange(self.rh) + 0.5 - self.rh / 2) / f  # (H,) ray slope, positive downwards
        self.yr = yr
        self.yr_col = yr[:, None].astype(np.float32)  # (H, 1)
        self._cam_dirs = np.stack([np.ones_like(self.xc), -self.xc], axis=1).astype(
            np.float32
        )  # (W, 2) camera frame
        self._cols = np.arange(self.rw)[None, :]
        k = float(np.max(np.abs(self.xc))) * 1.001  # tan of half the field of view (a hair wider)
        # Columns: forward * -1 (behind), left - k * forward (beyond left), -left - k * forward (beyond right).
        self._planes_t = np.array([[-1.0, -k, -k], [0.0, 1.0, -1.0]]).T.copy()  # (3, 2)

        # ---- segments, walls first
        seg = house.segments
        order = np.argsort(~seg.is_wall, kind="stable")
        self.seg_a = seg.a[order]
        self.seg_b = seg.b[order]
        self.seg_e = self.seg_b - self.seg_a
        self.seg_len = np.hypot(self.seg_e[:, 0], self.seg_e[:, 1])
        self._surfaces = Surfaces(self.seg_a, self.seg_b)
        self.seg_u0 = seg.u0[order]
        self.seg_tex = seg.texture[order]
        self.seg_height = np.where(seg.is_wall[order], cfg.wall_height, seg.height[order])
        self.n_walls = int(seg.is_wall.sum())
        self._n_seg = len(self.seg_a)
        self._ends_t = np.concatenate([self.seg_a, self.seg_b]).T.copy()  # (2, 2S): all a ends, then b ends

        # ---- the atlas: every texel the renderer can show, already shaded and scaled by brightness, so
        # that a frame is one gather with no per-pixel arithmetic on colours.
        #  - surfaces: for each texture and depth bin, the mip level and shading of that distance;
        #  - floor: for each (mip level, shading) pair that some floor row uses;
        #  - ceiling: one colour per row above the horizon; and the far colour.
        tint = np.asarray(house.lighting.tint, dtype=np.float32)
        self._tint = None if np.all(tint == 1.0) else tint
        self._atlas_chunks: list[np.ndarray] = []
        self._atlas_size = 0
        d_lo, d_hi = 0.1, max(cfg.max_range, 1.0) * 1.01  # a surface is never nearer than ~0.12 m
        ratio = (d_hi / d_lo) ** (1.0 / _DEPTH_BINS)
        self._bin_edges = d_lo * ratio ** np.arange(1, _DEPTH_BINS)  # (K-1,) searchsorted -> bin 0..K-1
        centres = d_lo * ratio ** (np.arange(_DEPTH_BINS) + 0.5)  # (K,)
        bin_light = self._shade(centres)
        texel = house.texture_sizes.min(axis=1) / TEX  # (T,) metres per texel at level 0
        # Mip level l while one pixel covers [2^l, 2^(l+1)) texels of level 0.
        level = np.clip(np.floor(np.log2(centres[None, :] / (f * texel[:, None]))), 0, _TEX_LEVELS - 1)
        level = level.astype(int)  # (T, K)
        # One shaded copy per (texture, light) pair that some face uses (sim2d.lighting: a face takes the
        # light at its midpoint, rounded, so a uniformly lit house has one copy per texture).
        face_light = house.lighting.face_levels((self.seg_a + self.seg_b) / 2)
        pairs, seg_variant = np.unique(
            np.stack([self.seg_tex.astype(np.float64), face_light], axis=1), axis=0, return_inverse=True
        )
        seg_variant = seg_variant.reshape(-1)
        mips = [mip_levels(img, _TEX_LEVELS) for img in house.texture_images]
        tex_off = np.zeros((len(pairs), _DEPTH_BINS), dtype=np.intp)
        for vi, (t_f, gain) in enumerate(pairs):
            t = int(t_f)
            for lvl, m in enumerate(mips[t]):
                bins = np.flatnonzero(level[t] == lvl)
                if bins.size:
                    tex_off[vi, bins] = self._add(m.astype(np.float32)[None], bin_light[bins] * gain)
        # Per (segment, depth bin) tables, row = segment * K + bin, so that a frame needs one gather per
        # table: ints (atlas offset, texel mask, log2 texels) and floats (texels per metre along u and v,
        # v at the camera's height, v at the top of the surface).
        tex = self.seg_tex
        n_side = (TEX >> level[tex]).astype(np.float64)  # (S, K) texels per side
        nsv = n_side / house.texture_sizes[tex, 1][:, None]
        self._tab_int = (
            np.stack([tex_off[seg_variant], n_side.astype(np.intp) - 1, _TEX_SHIFT - level[tex]], axis=-1)
            .reshape(-1, 3)
            .astype(np.int32)
        )
        self._tab_float = (
            np.stack(
                [
                    n_side / house.texture_sizes[tex, 0][:, None],
                    nsv,
                    cfg.camera_height * nsv,
                    self.seg_height[:, None] * nsv,
                ],
                axis=-1,
            )
            .reshape(-1, 4)
            .astype(np.float32)
        )
        self._max_furniture_height = max((fu.height for fu in house.furniture), default=0.0)
        # Piece of each furniture segment (segments are walls first, then each piece's edges in order).
        counts = [len(fu.vertices) for fu in house.furniture]
        self._seg_piece = np.concatenate(
            [np.full(self.n_walls, -1), np.repeat(np.arange(len(counts)), counts)]
        )
        if self.tops:
            self._top_tab, self._top_dh = top_tables(self, house, centres, bin_light)

        # ---- floor rows (below the horizon): ground depth, mip level, shading
        below = yr > 0
        self.floor_row0 = f0 = int(np.argmax(below)) if below.any() else self.rh
        g = cfg.camera_height / yr[f0:]  # (Hb,) forward depth of the floor seen by each row
        floor_mips = [m.astype(np.float32) for m in mip_levels(house.floor_image, _FLOOR_LEVELS)]
        res0 = house.floor_extent / floor_mips[0].shape[0]
        # Footprint of one pixel on the floor: g/f across, g^2/(f*h) along the view; take the geometric mean.
        foot = np.sqrt((g / f) * (g * g / (f * cfg.camera_height)))
        flevel = np.clip(np.round(np.log2(np.maximum(foot / res0, 1e-9))), 0, len(floor_mips) - 1).astype(int)
        # Shading quantised to 1/64 so that rows share shaded copies of a level (steps < 2% brightness).
        flight = np.round(self._shade(g) * house.lighting.level * 64.0) / 64.0
        far = g > cfg.max_range
        self.far_index = self._add(np.array([[[20.0, 20.0, 25.0]]]), 1.0)
        copies: dict[tuple[int, float], int] = {}
        row_off = np.empty(len(g), dtype=np.intp)
        for r in range(len(g)):
            if far[r]:
                row_off[r] = self.far_index
                continue
            key = (int(flevel[r]), float(flight[r]))
            if key not in copies:
                copies[key] = self._add(floor_mips[key[0]][None], key[1])
            row_off[r] = copies[key]
        n_row = np.array([m.shape[0] for m in floor_mips])[flevel]
        inv_cell = n_row / house.floor_extent  # texels per metre at each row's level
        self._floor_inv = inv_cell[:, None].astype(np.float32)  # (Hb, 1) texels per metre
        self._floor_gi = (g * inv_cell)[:, None].astype(
            np.float32
        )  # (Hb, 1) texels per unit of ray direction
        # Rows beyond max_range read the far colour: mask 0 makes x, y vanish, the offset points at it.
        self._floor_mask = np.where(far, 0, n_row - 1)[:, None].astype(np.int32)
        self._floor_shift = np.log2(n_row).astype(np.int32)[:, None]
        self._floor_off = row_off[:, None].astype(np.int32)
        self._floor_origin = house.floor_origin

        # ---- ceiling: one shaded colour per row above the horizon
        ceiling_depth = (cfg.wall_height - cfg.camera_height) / np.maximum(-yr[:f0], 1e-9)
        ceiling_light = self._shade(ceiling_depth) * house.lighting.level
        ceiling = house.ceiling_color[None, None, :] * ceiling_light[None, :, None]  # (1, f0, 3)
        ceiling = ceiling[None]  # (1, 1, f0, 3): one copy of f0 texels
        first = self._add(ceiling, 1.0) if f0 else 0
        self._ceiling = np.broadcast_to(
            (first + np.arange(f0, dtype=np.int32))[:, None], (f0, self.rw)
        ).copy()
        self.atlas = np.concatenate(self._atlas_chunks)  # (N,) 3-byte RGB items
        del self._atlas_chunks
        if self.atlas.size >= 2**31:
            raise ValueError(f"texture atlas of {self.atlas.size} texels is too large for int32 indices")

    def _shade(self, depth: np.ndarray) -> np.ndarray:
        """Distance shading: 1 at the camera, falling towards the ambient level far away."""
        c = self.cfg
        return c.ambient + (1.0 - c.ambient) * np.exp(
            -np.asarray(depth, dtype=np.float64) / c.shading_distance
        )

    def _add(self, texels: np.ndarray, light: np.ndarray | float) -> np.ndarray | int:
        """Append copies of texels (1, ..., 3) scaled by each light (times brightness, clipped) to the atlas.

        Returns the offset of each copy (an int for a scalar light)."""
        lights = np.atleast_1d(np.asarray(light, dtype=np.float32)) * np.float32(self.cfg.brightness)
        scaled = texels * lights.reshape((-1,) + (1,) * (texels.ndim - 1))  # (n, ..., 3)
        if self._tint is not None:  # the house light's colour cast (sim2d.lighting), per channel
            scaled = scaled * self._tint
        rgb = np.ascontiguousarray(np.clip(np.rint(scaled), 0, 255).astype(np.uint8))
        packed = rgb.view("V3").reshape(len(lights), -1)  # one 3-byte RGB item per texel
        offsets = self._atlas_size + packed.shape[1] * np.arange(len(lights))
        self._atlas_chunks.append(packed.ravel())
        self._atlas_size += packed.size
        return int(offsets[0]) if np.ndim(light) == 0 else offsets

    # ------------------------------------------------------------------------------------------------
    def raycast(self, x: float, y: float, yaw: float) -> dict[str, np.ndarray]:
        """Per column, for both layers (row 0: walls, row 1: furniture in front of the wall):
        depth (forward distance, _NO_HIT when nothing), segment index and position s in [0, 1] along it."""
        cos, sin = math.cos(yaw), math.sin(yaw)
        dirs = self._cam_dirs @ np.array([[cos, sin], [-sin, cos]], np.float32)  # (W, 2) world, forward 1
        ap, t_num = self._surfaces.from_origin(x, y)  # (S, 2), (S,): t_num < 0 on a front face
        # Signed offsets of both endpoints from the three planes bounding the view (behind, beyond the left
        # edge, beyond the right edge), > 0 outside: a segment with both endpoints beyond the same plane
        # cannot be seen. planes^T @ camera-from-world rotation, applied to all endpoints in one product.
        to_planes = self._planes_t @ np.array([[cos, sin], [-sin, cos]])  # (3, 2)
        off = to_planes @ self._ends_t - (to_planes @ (x, y))[:, None]  # (3, 2S): a ends, then b ends
        beyond = np.minimum(off[:, : self._n_seg], off[:, self._n_seg :]).max(axis=0) > 0  # (S,)
        front = np.flatnonzero((t_num < 0) & ~beyond)
        n_w = int(np.searchsorted(front, self.n_walls))  # front faces of walls come first
        n = len(front)
        # (W, n) 1 / forward depth of each column's ray on each front face, <= 0 where it misses
        inv_t, s_num, denom = inverse_depths(dirs, self._surfaces.e_perp_t[:, front], ap[front], t_num[front])
        layers = 3 if self.tops else 2
        k = np.zeros((layers, self.rw), dtype=np.intp)
        if n_w > 0:
            k[0] = np.argmax(inv_t[:, :n_w], axis=1)
        k[1:] = k[0]
        if n > n_w:
            k[1] = np.argmax(inv_t[:, n_w:], axis=1) + n_w
        cols = self._cols
        best = inv_t[cols, k]  # (layers, W) 1 / depth
        out: dict[str, np.ndarray] = {"dx": dirs[:, 0], "dy": dirs[:, 1]}
        if self.tops and n > n_w:
            # the second nearest piece (what shows above a low piece in front of it): faces of the nearest
            # piece masked out, as a ray meets a convex piece's front once (twice only at a shared corner)
            piece = self._seg_piece[front[n_w:]]
            others = np.where(piece[None, :] == piece[k[1] - n_w][:, None], 0.0, inv_t[:, n_w:])
            k[2] = np.argmax(others, axis=1) + n_w
            best[2] = others[cols[0], k[2] - n_w]
        hit = best > 1.0 / self.cfg.max_range
        hit[1:] &= best[1:] > best[0]  # furniture only in front of the wall
        depth = np.divide(1.0, best, out=np.full((layers, self.rw), _NO_HIT), where=hit)
        s = np.divide(s_num[cols, k], denom[cols, k], out=np.zeros((layers, self.rw)), where=hit)
        seg = front[k] if n else k
        if self.tops:
            out["t_out"] = far_sides(self, dirs, ap, t_num, beyond, seg, depth)
        return {"depth": depth, "seg": seg, "s": s, **out}

    def render(self, x: float, y: float, yaw: float) -> np.ndarray:
        """The (height, width, 3) uint8 RGB image seen from pose (x, y, yaw)."""
        cfg = self.cfg
        rh, rw, f = self.rh, self.rw, self.focal
        h_cam = cfg.camera_height
        rc = self.raycast(x, y, yaw)
        depth, seg = rc["depth"], rc["seg"]  # (2, W)

        # ---- per column and layer: depth bin (mip level and shading), atlas base, v = a - yr * b, v at the top
        key = seg * _DEPTH_BINS + np.searchsorted(self._bin_edges, depth)
        ti = self._tab_int[key]  # (2, W, 3) offset, mask, shift
        tf = self._tab_float[key]  # (2, W, 4) texels/m along u and v, v at camera height, v at the top
        u = self.seg_u0[seg] + rc["s"] * self.seg_len[seg]  # metres along the surface
        base = ti[..., 0] + ((u * tf[..., 0]).astype(np.int32) & ti[..., 1])
        b = depth.astype(np.float32) * tf[..., 1]

        # ---- background: ceiling above the horizon, the floor below the highest row a wall leaves free
        centre = rh / 2 - 0.5
        wall_cols = np.flatnonzero(depth[0] < _NO_HIT)
        d_far = float(depth[0].max())
        f0 = self.floor_row0
        r0 = min(rh, max(f0, math.floor(centre + f * h_cam / d_far) - 2))
        idx = np.empty((rh, rw), dtype=np.int32)  # int32: per-pixel integer work is ~2x faster than int64
        idx[:f0] = self._ceiling
        idx[f0:r0] = self.far_index  # every column sees a wall there: no floor visible
        rows = slice(r0 - f0, None)
        ox, oy = self._floor_origin
        # Texel coordinates (x, y) of the floor point each pixel sees: origin + ground depth * ray direction.
        start = (
            np.array([(x - ox), (y - oy)], np.float32)[:, None, None] * self._floor_inv[rows]
        )  # (2, Hf, 1)
        ray = np.stack([rc["dx"], rc["dy"]]).astype(np.float32)[:, None, :]  # (2, 1, W)
        fxy = (start + self._floor_gi[rows] * ray).astype(np.int32)  # (2, Hf, W)
        fxy &= self._floor_mask[rows]
        fxy[1] <<= self._floor_shift[rows]
        fxy[1] += fxy[0]
        np.add(fxy[1], self._floor_off[rows], out=idx[r0:])

        # ---- walls, then furniture far to near (painter's order), each within the bounding box of rows and
        # columns it can cover
        heights = (cfg.wall_height, self._max_furniture_height)
        for layer in (0, 2, 1) if self.tops else (0, 1):
            cols = wall_cols if layer == 0 else np.flatnonzero(depth[layer] < _NO_HIT)
            if cols.size == 0:
                continue
            c0, c1 = int(cols[0]), int(cols[-1]) + 1
            d_near = float(depth[layer, c0:c1].min())
            # Rows where z in [0, height) can show: yr in ((h_cam - height) / d, h_cam / d].
            t0 = max(0, math.floor(centre + f * (h_cam - heights[min(layer, 1)]) / d_near) - 1)
            b1 = min(rh, math.ceil(centre + f * h_cam / d_near) + 2)
            cs = slice(c0, c1)
            if layer and self.tops:  # the top of a piece lower than the camera, where the column sees it
                draw_tops(self, idx, rc, layer, cs)
            if b1 <= t0:
                continue
            v = tf[layer, cs, 2] - self.yr_col[t0:b1] * b[layer, cs]  # (h, w) texture row
            vis = v >= 0
            vis &= v < tf[layer, cs, 3]
            vi = v.astype(np.int32)
            vi &= ti[layer, cs, 1]
            vi <<= ti[layer, cs, 2]
            vi += base[layer, cs]
            np.putmask(idx[t0:b1, cs], vis, vi)

        img = np.take(self.atlas, idx).view(np.uint8).reshape(rh, rw, 3)  # one 3-byte item per pixel
        if cfg.supersample > 1:  # box filter: add the ss x ss sub-images, round, divide
            ss = cfg.supersample
            acc = np.full((cfg.height, cfg.width, 3), (ss * ss) // 2, dtype=np.uint32)
            for i in range(ss):
                for j in range(ss):
                    acc += img[i::ss, j::ss]
            img = (acc // (ss * ss)).astype(np.uint8)
        return img
