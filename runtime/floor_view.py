"""The floor ahead in a camera image, and a taught view moved as the floor would move (for
runtime.obstruction): which tiles see the path ahead, where the robot is relative to a taught view, and the
taught view warped to that pose by the floor plane.

A pinhole camera ``height_m`` above a flat floor, looking straight ahead and level, sees the floor point
``X`` metres ahead and ``Y`` to the left at pixel ``(H / 2 + f h / X, W / 2 - f Y / X)``. So, given the
robot's pose relative to where a view was taught, every pixel of the floor in the current image can be
looked up in the taught image: floor lines up, whatever stands on it (a box) does not. Images are compared
as the patch matcher compares them (``downsample``-pooled, ``patch`` x ``patch`` tiles normalised per
channel), after pooling; the warp takes the nearest pooled pixel.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from vtr.runtime.contracts import CAMERA
from vtr.runtime.frame import Frame
from vtr.runtime.matching import Matcher, pool, pooled_sums
from vtr.runtime.preprocess import planar_levels

#: The robot's pose relative to a taught view's: metres ahead, metres left, radians turned left.
Offset = tuple[float, float, float]


@dataclass(frozen=True)
class Camera:
    """A pinhole camera looking straight ahead, level, square pixels (as sim2d renders)."""

    height: int = CAMERA.height
    width: int = CAMERA.width
    fov_deg: float = CAMERA.fov_deg or 90.0
    height_m: float = CAMERA.height_m or 0.3

    @property
    def focal_px(self) -> float:
        return 0.5 * self.width / math.tan(math.radians(self.fov_deg) / 2)

    def rays(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Slopes of the rays through (continuous) pixel coordinates: downwards and to the right, per metre
        ahead."""
        f = self.focal_px
        return (rows - self.height / 2) / f, (cols - self.width / 2) / f


def path_weights(
    camera: Camera, tile_px: int, half_width_m: float, near_m: float, far_m: float
) -> np.ndarray:
    """(tiles,) share of each ``tile_px``-pixel tile (row by row) whose pixels see the floor of the corridor
    ahead: ``near_m`` to ``far_m`` ahead, within ``half_width_m`` of the camera's axis."""
    h, w = camera.height, camera.width
    if h % tile_px or w % tile_px:
        raise ValueError(f"image {h}x{w} is not a multiple of the tile size {tile_px}")
    down, side = camera.rays(np.arange(h) + 0.5, np.arange(w) + 0.5)
    ahead = camera.height_m / np.where(down > 0, down, np.nan)  # nan above the horizon: no floor
    with np.errstate(invalid="ignore"):
        inside = ((ahead >= near_m) & (ahead <= far_m))[:, None] & (
            np.abs(side)[None, :] * ahead[:, None] <= half_width_m
        )
    return inside.reshape(h // tile_px, tile_px, w // tile_px, tile_px).mean(axis=(1, 3)).ravel()


def tile_floor_points(camera: Camera, tile_px: int, tiles: np.ndarray, per_side: int = 4) -> np.ndarray:
    """(tiles, per_side ** 2, 2) floor points (x ahead, y left, metres; 1 km ahead above the horizon) that a
    ``per_side`` x ``per_side`` grid of pixels of each tile (indices row by row) sees."""
    per_row = camera.width // tile_px
    offsets = (np.arange(per_side) + 0.5) * tile_px / per_side
    rows = (np.asarray(tiles) // per_row * tile_px)[:, None] + offsets  # (T, per_side)
    cols = (np.asarray(tiles) % per_row * tile_px)[:, None] + offsets
    down, right = camera.rays(rows, cols)
    ahead = camera.height_m / np.where(down > 0, down, camera.height_m / 1e3)  # (T, per_side)
    x = np.repeat(ahead, per_side, axis=1)
    y = -np.tile(right, per_side) * x
    return np.stack([x, y], axis=-1)


def path_ahead(poses: np.ndarray, position: float, length: float, step: float = 0.1) -> np.ndarray:
    """(M, 2) the taught path from route position ``position`` (subgoal units) onwards, in the frame of the
    taught pose there (x ahead, y left, metres), for ``length`` metres of travel or to the route's end, a
    point every ``step`` metres: the floor the robot is about to drive over, as it lies from where the
    localiser places it."""
    n = len(poses)
    k = max(0, min(int(math.floor(position)), n - 2)) if n > 1 else 0
    t = min(max(position - k, 0.0), 1.0) if n > 1 else 0.0
    x0, y0, a0 = poses[k]
    if n > 1:
        x1, y1, a1 = poses[k + 1]
        x0, y0, a0 = x0 + t * (x1 - x0), y0 + t * (y1 - y0), a0 + t * math.remainder(a1 - a0, math.tau)
    xy = np.vstack([[x0, y0], poses[k + 1 :, :2]])
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    end = min(length, float(arc[-1]))
    # every ``step`` metres along it (a chord of a 0.5 m radius bend strays 2.5 mm from it)
    at = np.append(np.arange(0.0, end, step), end)
    xy = np.stack([np.interp(at, arc, xy[:, 0]), np.interp(at, arc, xy[:, 1])], axis=1) - (x0, y0)
    c, s = math.cos(a0), math.sin(a0)
    return np.stack([c * xy[:, 0] + s * xy[:, 1], -s * xy[:, 0] + c * xy[:, 1]], axis=1)


def near_path(
    points: np.ndarray, path: np.ndarray, half_width_m: float, near_m: float, far_m: float
) -> np.ndarray:
    """(P,) whether each floor point (P, 2) (x ahead, y left) lies within ``half_width_m`` of the polyline
    ``path`` (M, 2), at a stretch of it ``near_m`` to ``far_m`` along from its start."""
    seg = np.diff(path, axis=0)
    length2 = (seg * seg).sum(axis=1)
    keep = length2 > 1e-12  # a turn in place adds no floor
    if not keep.any():
        return np.zeros(len(points), dtype=bool)
    (ax, ay), (sx, sy), length2 = path[:-1][keep].T, seg[keep].T, length2[keep]
    length = np.sqrt(length2)
    arc0 = np.cumsum(length) - length
    rx, ry = points[:, :1] - ax, points[:, 1:] - ay  # (P, S)
    u = np.clip((rx * sx + ry * sy) / length2, 0.0, 1.0)
    rx -= u * sx
    ry -= u * sy
    gap2 = rx * rx + ry * ry
    nearest = np.argmin(gap2, axis=1)
    rows = np.arange(len(points))
    along = arc0[nearest] + u[rows, nearest] * length[nearest]
    return (gap2[rows, nearest] <= half_width_m**2) & (along >= near_m) & (along <= far_m)


def taught_offset(poses: np.ndarray | None, position: float) -> tuple[int, Offset]:
    """The subgoal ``k`` at or behind route position ``position`` (subgoal units) and the taught pose there
    relative to subgoal ``k``'s, interpolated between the taught poses (zero where they are unknown)."""
    n = 0 if poses is None else len(poses)
    if n < 2 or poses is None:
        return max(0, min(int(math.floor(position)), n - 1)), (0.0, 0.0, 0.0)
    k = max(0, min(int(math.floor(position)), n - 2))
    t = min(max(position - k, 0.0), 1.0)
    here, there = poses[k].tolist(), poses[k + 1].tolist()  # Python floats: the same arithmetic, faster
    if not all(map(math.isfinite, (*here, *there))):
        return k, (0.0, 0.0, 0.0)
    return k, relative_pose(here, there, t)


def relative_pose(origin: Sequence[float], pose: Sequence[float], t: float = 1.0) -> Offset:
    """``pose`` (x, y, yaw) seen from ``origin`` (ahead, left, turned left), or the share ``t`` of the way
    there (a straight blend of position and turn)."""
    (x0, y0, a0), (x1, y1, a1) = origin, pose
    dx, dy = t * (x1 - x0), t * (y1 - y0)
    c, s = math.cos(a0), math.sin(a0)
    return c * dx + s * dy, -s * dx + c * dy, t * math.remainder(a1 - a0, math.tau)


class FloorTiles:
    """Some tiles of an image (``tiles``, indices row by row, all at or below the horizon's tile row): their
    features, and those of a taught view warped by the floor to an offset and shifted by up to
    ``shift_rows`` x ``shift_cols`` pooled pixels each way (the robot is a little off the taught pose the
    localiser gives it: a few centimetres or degrees move the floor near it by pixels)."""

    def __init__(
        self, camera: Camera, tiles: np.ndarray, matcher: Matcher, shift_rows: int = 1, shift_cols: int = 2
    ) -> None:
        self.camera, self.tiles, self.matcher = camera, np.asarray(tiles), matcher
        ds, p = matcher.cfg.downsample, matcher.cfg.patch
        h, w = camera.height, camera.width
        per_row = w // (ds * p)
        tile_rows, tile_cols = self.tiles // per_row, self.tiles % per_row
        # the band of pooled rows kept: from the horizon (or the first tile, if higher) to the bottom
        self.top = min(int(tile_rows.min()) * p, h // 2 // ds)
        self.shape = (h // ds - self.top, w // ds)
        down, self._side = camera.rays(
            np.arange(self.top, h // ds) * ds + ds / 2, np.arange(w // ds) * ds + ds / 2
        )
        # the floor point each pooled pixel sees is A ahead (per row) and -side * A to the left (per column);
        # rows at or above the horizon see no floor and are not warped
        self._sky = int(np.count_nonzero(down <= 0))
        self._ahead = (camera.height_m / down[self._sky :]).astype(np.float32)
        self._side = self._side.astype(np.float32)
        self._still = np.arange(self._sky * self.shape[1]).reshape(self._sky, self.shape[1])
        # each tile's origin in the band, every shift of it kept inside the band, and the flat indices of the
        # values of each (shift, tile) in a planar band, in the matcher's order (channel, row, column)
        r0, c0 = tile_rows * p - self.top, tile_cols * p
        dr, dc = np.meshgrid(np.arange(-shift_rows, shift_rows + 1), np.arange(-shift_cols, shift_cols + 1))
        r = np.clip(r0[None] + dr.reshape(-1, 1), 0, self.shape[0] - p)  # (shifts, tiles)
        c = np.clip(c0[None] + dc.reshape(-1, 1), 0, self.shape[1] - p)
        i, j = np.divmod(np.arange(p * p), p)
        plane = self.shape[0] * self.shape[1]
        pixel = (r[..., None] + i) * self.shape[1] + c[..., None] + j  # (shifts, tiles, p * p)
        self._index = (pixel[:, :, None, :] + plane * np.arange(3)[:, None]).astype(np.intp)
        self.centre = (dr.size - 1) // 2  # the unshifted windows

    def pool(self, image: np.ndarray) -> np.ndarray:
        """(3, band rows, cols) float32 sums of ``downsample`` x ``downsample`` blocks of ``image``'s band,
        from its planar levels (one conversion per frame, shared with the matcher and the policy); a frame's
        are its pooled sums, made once per frame and shared with the localiser's matcher (the same bits)."""
        ds = self.matcher.cfg.downsample
        if isinstance(image, Frame):
            return pooled_sums(image, ds)[:, self.top :]
        return pool(planar_levels(image)[:, self.top * ds :], ds)  # sums of integers: the same bits

    def features(
        self, band: np.ndarray, which: np.ndarray | None = None, shifted: bool = False
    ) -> np.ndarray:
        """(tiles, D) patch features of a pooled band's tiles (``which``: those of ``tiles`` at these
        positions, default all); ``shifted``: (shifts, tiles, D), every shifted window of each."""
        index = self._index if shifted else self._index[self.centre : self.centre + 1]
        if which is not None:
            index = index[:, which]
        out = self.matcher.normalised(band.ravel().take(index))
        return out if shifted else out[0]

    def colours(self, band: np.ndarray, which: np.ndarray | None = None, shifted: bool = False) -> np.ndarray:
        """(tiles, 3) chromaticity of a pooled band's tiles (``which`` as for :meth:`features`; ``shifted``:
        (shifts, tiles, 3), every shifted window of each): each tile's mean per channel over the band's
        floor rows' mean per channel (a colour cast or a gain drops out), then over their sum (a light that
        darkens one side, the same in every channel, drops out too). What the patch features normalise away:
        a plain tile's colour."""
        index = self._index if shifted else self._index[self.centre : self.centre + 1]
        if which is not None:
            index = index[:, which]
        means = band.ravel().take(index).mean(axis=-1)  # (shifts, tiles, 3)
        means /= np.maximum(band[:, self._sky :].mean(axis=(1, 2)), np.float32(1e-3))
        means /= np.maximum(means.sum(axis=-1, keepdims=True), np.float32(1e-6))
        return means if shifted else means[0]

    def frame_features(self, frame: Frame, which: np.ndarray) -> np.ndarray:
        """:meth:`features` of a frame's pooled band (``which``, unshifted), the same bits, from the tiles'
        centred values and spreads the localiser's matcher made for the frame (``Matcher.moments``)."""
        centred, spread = self.matcher.moments(frame)
        tiles = self.tiles[which]
        return np.divide(centred[tiles], self.matcher.floored(spread[tiles])).reshape(len(tiles), -1)

    def warp(self, band: np.ndarray, offset: Offset) -> np.ndarray:
        """A taught pooled band as the floor looks from ``offset`` (nearest pooled pixel; pixels above the
        horizon stay)."""
        dx, dy, turn = offset
        if not (dx or dy or turn):
            return band
        rows, cols = self.shape
        row, col = self._source(offset)
        index = np.clip(row, 0, rows - 1, out=row).astype(np.intp) * cols
        index += np.clip(col, 0, cols - 1, out=col).astype(np.intp)
        if self._sky:
            index = np.vstack([self._still, index])
        return band.reshape(3, -1)[:, index]

    def seen(self, offset: Offset) -> np.ndarray:
        """(tiles,) whether the taught view saw the floor each tile's centre sees from ``offset``: a tile
        whose floor lay past the taught view's edge (a robot turned or beside the taught pose sees floor
        the teach did not) cannot match it, and is no evidence of anything."""
        rows, cols = self.shape
        row, col = self._source(offset)
        p = self.matcher.cfg.patch
        per_row = self.camera.width // (self.matcher.cfg.downsample * p)
        r = np.clip((self.tiles // per_row) * p - self.top + p // 2 - self._sky, 0, len(row) - 1)
        c = (self.tiles % per_row) * p + p // 2
        at_r, at_c = row[r, c], col[r, c]
        return (at_r >= 0) & (at_r < rows) & (at_c >= 0) & (at_c < cols)

    def _source(self, offset: Offset) -> tuple[np.ndarray, np.ndarray]:
        """(floor rows, cols) float pooled band coordinates, in the taught view, of the floor point each
        pooled pixel below the horizon sees from ``offset``."""
        dx, dy, turn = offset
        ds = self.matcher.cfg.downsample
        h, w, f = self.camera.height, self.camera.width, self.camera.focal_px
        c, s = math.cos(turn), math.sin(turn)
        # in the taught camera's frame the floor point is dx + A (c + s side) ahead, dy + A (s - c side) left
        ahead = np.multiply.outer(self._ahead, np.float32(c) + np.float32(s) * self._side)
        ahead += np.float32(dx)
        np.maximum(ahead, np.float32(1e-3), out=ahead)  # behind the taught camera: the nearest row is best
        inverse = np.reciprocal(ahead, out=ahead)
        left = np.multiply.outer(self._ahead, np.float32(s) - np.float32(c) * self._side)
        left += np.float32(dy)
        left *= inverse
        row = inverse * np.float32(f * self.camera.height_m / ds)
        row += np.float32(h / 2 / ds - self.top)
        col = np.multiply(left, np.float32(-f / ds), out=left)
        col += np.float32(w / 2 / ds)
        return row, col


__all__ = [
    "Camera",
    "FloorTiles",
    "Offset",
    "near_path",
    "path_ahead",
    "path_weights",
    "taught_offset",
    "tile_floor_points",
]
