"""Image comparison for subgoal switching: the paper's raw error, and one that survives changed light.

Two methods, both "smaller is closer", both computed on features the caller can cache per subgoal:

- ``raw`` (the paper's, ``--profile paper``): mean absolute pixel difference on 0..255 (``image_error``). A 30%
  brightness change moves it by 30-40, more than any sensible switch threshold.
- ``patch`` (the default): each image is averaged down by ``downsample``, cut into ``patch`` x ``patch``
  tiles, and every tile of every colour channel is normalised to zero mean and unit variance (QVPR
  teach-repeat's patch normalisation, here per channel). A gain and an offset per tile and channel
  cancel, so global brightness, contrast, a colour cast and one side of the view darker (a light that
  varies slowly across the image) all drop out. Each tile then scores the mean absolute difference of its
  normalised values, and the image distance is the mean of the best ``1 - trim`` fraction of tile scores:
  a re-textured wall or a moved chair changes some tiles, and the worst tiles are the ones left out, so one
  changed region cannot dominate. Tiles with almost no texture (a plain wall) have their spread floored at
  ``std_floor`` so sensor noise is not blown up into a pattern.

The patch distance is in units of standard deviations: 0 for the same view, about 1.13 (2 / sqrt(pi)) for
two unrelated textures. Measured cost and discriminability: ``python -m studies.matching_study`` (a study, not installed).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from vtr.runtime.frame import Frame, as_frame, planar
from vtr.runtime.preprocess import image_error
from vtr.runtime.wire_json import BadFrameError

MATCH_METHODS = ("raw", "patch")


@functools.cache
def _ones(n: int, dtype: type) -> np.ndarray:
    return np.ones(n, dtype=dtype)


def pool(levels: np.ndarray, f: int) -> np.ndarray:
    """(C, H / f, W / f) sums of ``f`` x ``f`` blocks of planar levels (C, H, W), in a new array (``levels``
    itself when f = 1). Planar, so every add runs over contiguous rows or pairs; sums of integers, which float32
    holds exactly whatever the order of the adds (float64 past f = 256), so any pooling of the same levels
    gives the same bits."""
    c, h, w = levels.shape
    if h % f or w % f:
        raise BadFrameError(f"image {h}x{w} is not a multiple of the pooling factor {f}")
    if f == 1:
        return levels
    if 255 * f * f >= 2**24:
        levels = levels.astype(np.float64)
    rows = levels.reshape(c, h // f, f, w)
    x = rows[:, :, 0] + rows[:, :, 1]
    for dy in range(2, f):
        x += rows[:, :, dy]
    cols = x.reshape(c, h // f, w // f, f)
    y = cols[..., 0] + cols[..., 1]
    for dx in range(2, f):
        y += cols[..., dx]
    return y


def pooled_sums(frame: Frame, f: int) -> np.ndarray:
    """A frame's (3, H / f, W / f) ``f`` x ``f`` block sums of its planar levels, made once per frame and kept
    on it (read-only): the localiser's matcher and the obstruction detector's floor tiles share them."""
    return frame.derived(("pooled_sums", f), lambda fr: _read_only(pool(fr.levels, f)))


def _read_only(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


@dataclass(frozen=True)
class MatchConfig:
    """How two images are compared (see the module docstring)."""

    #: "raw": the paper's mean absolute pixel error (0..255); "patch": patch-normalised, trimmed.
    method: str = "patch"
    #: Average-pool factor before tiling (128 -> 64 with 2): fewer, less noisy values, 4x cheaper.
    downsample: int = 2
    #: Tile side in (downsampled) pixels; the image side must be a multiple of downsample * patch.
    patch: int = 8
    #: Fraction of the worst tile scores left out of the mean (0 = plain mean, 0.5 = lower half).
    trim: float = 0.5
    #: Floor on a tile's standard deviation, in 0..255 pixel units.
    std_floor: float = 4.0

    def __post_init__(self) -> None:
        if self.method not in MATCH_METHODS:
            raise ValueError(f"match method must be one of {MATCH_METHODS}, got {self.method!r}")
        if self.downsample < 1 or self.patch < 2:
            raise ValueError(f"downsample must be >= 1 and patch >= 2, got {self.downsample}, {self.patch}")
        if not 0.0 <= self.trim < 1.0:
            raise ValueError(f"trim must be in [0, 1), got {self.trim}")
        if not (math.isfinite(self.std_floor) and self.std_floor > 0):
            raise ValueError(f"std_floor must be a positive number, got {self.std_floor!r}")

    @classmethod
    def paper(cls) -> MatchConfig:
        return cls(method="raw")


class Matcher:
    """Turns images into comparable features and scores them; ``features`` is what a caller caches."""

    def __init__(self, cfg: MatchConfig | None = None) -> None:
        self.cfg = cfg or MatchConfig()

    def features(self, images: Frame | np.ndarray) -> np.ndarray:
        """A :class:`~vtr.runtime.frame.Frame` or (H, W, 3) uint8 image, or a (B, H, W, 3) uint8 stack ->
        features of the same leading shape.

        raw: the uint8 images themselves; patch: float32 (B, tiles, patch * patch * 3), normalised. A frame's
        features are made once per frame and matcher settings and kept on it (read-only: whoever asks again
        in the same step, the localiser or a study, gets the same array), from its pooled sums
        (:func:`pooled_sums`, shared with the obstruction detector); a stack is pooled image by image the
        same way, so that a subgoal's features are bit for bit those of the same view seen live.
        """
        if isinstance(images, Frame) or images.ndim == 3:
            frame = as_frame(images)
            return frame.image if self.cfg.method == "raw" else frame.derived(self._key, self._frame_features)
        if images.dtype != np.uint8 or images.ndim != 4 or images.shape[-1] != 3:
            raise BadFrameError(
                f"expected uint8 (H, W, 3) or (B, H, W, 3) images, got {images.shape} {images.dtype}"
            )
        if self.cfg.method == "raw":
            return images
        f = self.cfg.downsample
        return np.concatenate([self._normalised(self._tiles(pool(planar(image), f))) for image in images])

    @property
    def _key(self) -> tuple[str, MatchConfig]:
        return ("patch_features", self.cfg)

    def _frame_features(self, frame: Frame) -> np.ndarray:
        centred, spread = self.moments(frame)
        features = np.divide(centred, self.floored(spread)).reshape(centred.shape[0], -1)
        features.flags.writeable = False
        return features

    def moments(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """A frame's (tiles, C, patch * patch) tile values less their means and (tiles, C, 1) spreads (before
        the floor), read-only: made once per frame, downsample and patch, and shared by every matcher with
        those (the localiser's, the obstruction detector's: only their floors differ). Each tile is
        normalised on its own, so its features from these have the bits :meth:`normalised` gives it."""
        key = ("patch_moments", self.cfg.downsample, self.cfg.patch)
        return frame.derived(key, self._frame_moments)

    def _frame_moments(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        tiles = self._tiles(pooled_sums(frame, self.cfg.downsample))[0]
        spread = self._centre(tiles)
        tiles.flags.writeable = spread.flags.writeable = False
        return tiles, spread

    def _centre(self, tiles: np.ndarray) -> np.ndarray:
        """In place: (..., C, p * p) tiles of pooled sums less their means; returns their (..., C, 1) spreads."""
        p = self.cfg.patch
        # the mean: the sums are of integers (pooled levels) below 2**24, exact in any order, so a BLAS
        # product gives the bits ndarray.mean's pairwise sum does
        tiles -= np.matmul(tiles, _ones(p * p, tiles.dtype))[..., None] / (p * p)
        return np.sqrt(np.einsum("...i,...i->...", tiles, tiles) / (p * p))[..., None]

    def floored(self, spread: np.ndarray) -> np.ndarray:
        """Tile spreads (pooled-sum units) floored at ``std_floor`` (0..255 units): what features divide by."""
        f = self.cfg.downsample
        return np.maximum(spread, np.float32(self.cfg.std_floor * f * f))

    def _tiles(self, pooled: np.ndarray) -> np.ndarray:
        """(1, tiles, C, p * p) tiles of one image's pooled sums (C, H / f, W / f), in a new array; of a stack
        of them (S, C, H / f, W / f), every image's tiles in turn (S * tiles)."""
        p = self.cfg.patch
        *stack, c, h, w = pooled.shape
        if h % p or w % p:
            f = self.cfg.downsample
            raise BadFrameError(f"image {h * f}x{w * f} is not a multiple of downsample * patch = {f * p}")
        hp, wp, s = h // p, w // p, int(np.prod(stack, dtype=int))
        # (S, C, hp, p, wp, p) -> (1, S * tiles, C, p * p): a copy (a view of read-only levels when f = 1 and
        # one tile)
        tiles = (
            pooled.reshape(s, c, hp, p, wp, p).transpose(0, 2, 4, 1, 3, 5).reshape(1, s * hp * wp, c, p * p)
        )
        return (tiles if tiles.flags.writeable else tiles.copy()).astype(np.float32, copy=False)

    def _normalised(self, tiles: np.ndarray) -> np.ndarray:
        """(B, tiles, C, p * p) pooled sums -> (B, tiles, C * p * p) features, normalised in place."""
        tiles /= self.floored(self._centre(tiles))
        b, n, c, pp = tiles.shape
        return tiles.reshape(b, n, c * pp)

    def normalised(self, tiles: np.ndarray) -> np.ndarray:
        """(B, tiles, C, patch * patch) float32 tiles of pooled sums (each value the sum of a downsample x
        downsample block, as :meth:`features` pools) -> patch features, normalised in place: for callers
        that sample their own tiles (runtime.obstruction warps a taught view)."""
        return self._normalised(tiles)

    def shifted_features(self, frame: Frame, shifts: tuple[int, ...]) -> np.ndarray:
        """(S, rows, columns - 1, D) a frame's patch features with its tile grid cut each of ``shifts`` pooled
        pixels to the right (0 < |shift| < patch): the view of a robot turned that many pooled pixels' worth
        to the left, lined up with a taught view. The edge column of tiles a shift leaves half outside the
        image is dropped: a shift to the right faces the taught grid's columns 0 .. columns - 2, one to the
        left 1 .. columns - 1 (:meth:`shifted_distances`). Made once per frame and shifts, in one batch."""
        return frame.derived(
            ("shifted_features", tuple(shifts), self.cfg), lambda fr: self._shifted(fr, shifts)
        )

    def tile_columns(self, frame: Frame) -> int:
        """Tiles across a frame."""
        return frame.shape[1] // (self.cfg.downsample * self.cfg.patch)

    def _shifted(self, frame: Frame, shifts: tuple[int, ...]) -> np.ndarray:
        """:meth:`shifted_features`' batch, made (and its shifts checked) once per frame, not per call."""
        p = self.cfg.patch
        if not all(0 < abs(s) < p for s in shifts):
            raise ValueError(f"shifts must be 1..{p - 1} pooled pixels either way, got {shifts!r}")
        if self.tile_columns(frame) < 2:
            raise ValueError(f"a {frame.shape[1]} px wide image has too few tiles across to shift")
        pooled = pooled_sums(frame, self.cfg.downsample)
        h, w = pooled.shape[1:]
        hp, wp = h // p, w // p
        span = (wp - 1) * p
        cuts = np.stack(
            [pooled[:, :, s if s > 0 else p + s :][:, :, :span] for s in shifts]
        )  # (S, c, h, span)
        features = self._normalised(self._tiles(cuts)).reshape(len(shifts), hp, wp - 1, -1)
        features.flags.writeable = False
        return features

    def shifted_distances(
        self, frame: Frame, shifts: tuple[int, ...], others: np.ndarray, only: int | None = None
    ) -> np.ndarray:
        """(S, K) :meth:`distances` of a frame cut each of ``shifts`` pooled pixels across
        (:meth:`shifted_features`) to K features of unshifted views (a (K, tiles, D) stack), over the tiles it
        faces: a column range of each view's tile grid, read in place (gathering would copy the stack);
        ``only``: the index of the one shift to compare (its row alone is filled, the others NaN)."""
        features = self.shifted_features(frame, shifts)
        k, n, d = others.shape
        wp = self.tile_columns(frame)
        grid = others.reshape(k, n // wp, wp, d)
        out = np.full((len(shifts), k), np.nan)
        picked = range(len(shifts)) if only is None else (only,)
        for first in (0, 1):  # a shift to the right faces columns from 0, one to the left from 1
            at = [i for i in picked if (shifts[i] > 0) == (first == 0)]
            if not at:
                continue
            # every shift that way in one batch: (S', K, rows, columns - 1, D)
            diff = grid[None, :, :, first : first + wp - 1] - features[at, None]
            np.abs(diff, out=diff)
            # reduced as distances() reduces its (K, tiles, D) stack, a row per shift and view
            scores = self._trimmed(np.add.reduce(diff.reshape(len(at) * k, -1, d), axis=-1) / d)
            out[at] = scores.reshape(len(at), k)
        return out

    def _trimmed(self, per_tile: np.ndarray) -> np.ndarray:
        """(K,) the mean of each row's best ``1 - trim`` share of (K, tiles) tile scores, float64."""
        keep = max(1, int(round(per_tile.shape[1] * (1.0 - self.cfg.trim))))
        if keep < per_tile.shape[1]:
            per_tile = np.partition(per_tile, keep - 1, axis=1)[:, :keep]
        return (np.add.reduce(per_tile, axis=1) / keep).astype(np.float64)

    def distance(self, a: np.ndarray, b: np.ndarray) -> float:
        """Distance between two features (or images for raw) from :meth:`features`."""
        if self.cfg.method == "raw":
            return image_error(a, b)
        if a.shape != b.shape:
            raise ValueError(f"feature shape {a.shape} differs from {b.shape}")
        # distances() for one pair, without the stack: the same operations on the same values, so the
        # same number (the controller compares distances from both)
        diff = b - a
        np.abs(diff, out=diff)
        return float(self._trimmed((np.add.reduce(diff, axis=-1) / diff.shape[-1])[None])[0])

    def distances(self, feature: np.ndarray, others: np.ndarray) -> np.ndarray:
        """(K,) distances from one feature to each of K features (a stack from :meth:`features`)."""
        if self.cfg.method == "raw":
            return np.array([image_error(feature, o) for o in others], dtype=np.float64)
        if feature.shape != others.shape[1:]:
            raise ValueError(f"feature shape {feature.shape} differs from {others.shape[1:]}")
        # a fresh array on purpose: one kept for it (440 KB for 9 subgoals) made the light-matched step
        # ~70 us slower on the 2-core machine (512 KB of L2 a core), where a fresh one reuses memory just
        # freed, still in cache (studies.step_profile_lockstep; benchmarks/results/latency_step_s3.md)
        diff = others - feature
        np.abs(diff, out=diff)
        # reduce / count: what ndarray.mean computes, without its Python-level bookkeeping
        return self._trimmed(np.add.reduce(diff, axis=-1) / diff.shape[-1])  # (K, tiles) tile scores

    def tile_distances(self, feature: np.ndarray, others: np.ndarray) -> np.ndarray:
        """(K, tiles) per-tile scores of one patch feature against each of K (``others``: (K, tiles, D) or
        one (tiles, D)): the untrimmed values whose best share :meth:`distances` averages. Tiles run row by
        row over the image (``image side / (downsample * patch)`` of them per row)."""
        if self.cfg.method != "patch":
            raise ValueError("tile distances need patch matching (method='patch')")
        others = others[None] if others.ndim == feature.ndim else others
        if feature.shape != others.shape[1:]:
            raise ValueError(f"feature shape {feature.shape} differs from {others.shape[1:]}")
        diff = others - feature
        np.abs(diff, out=diff)
        return np.add.reduce(diff, axis=-1) / diff.shape[-1]

    def image_distance(self, a: np.ndarray, b: np.ndarray) -> float:
        """Convenience: distance between two uint8 images (features computed on the fly)."""
        return self.distance(self.features(a), self.features(b))
