"""Repeat-time light compensation for a policy trained on images lit as in the teach run.

The light between teach and repeat changes (evening, a lamp off); a network that has only seen the taught
light steers wrongly when the current image is darker, brighter or tinted. ``match_statistics`` moves the
current image's per-channel mean and standard deviation onto the subgoal's (the taught light), which
undoes any global gain, offset or colour cast, before the network sees the pair; ``remove_side_ramp``
first evens out a left-to-right gain (one side of the view darker). DVMPC recolours the same
way (there the subgoal towards the current image); we recolour the current image, so the network keeps
seeing images lit as in training. It leaves geometry alone: where things are in the image does not move.

``LightMatchedPolicy`` wraps any policy (``predict(current, subgoal)``) with it: what `vtr repeat`'s default
profile runs (``--profile paper`` leaves it out). A model trained with augmentation and ``STANDARDISED``
preprocessing needs it less. The wrapper works on planar float32 (3, H, W), the layout the network takes, and
hands the result to the policy as a frame of those levels (``Frame.from_levels``) without a uint8 round trip:
the values are those of ``to_nchw(match_statistics(remove_side_ramp(current)))`` exactly. About 0.07 ms per
step on 128x128 (0.17 ms before, 1.4 ms before its reductions went through BLAS; the condition-suite results
were measured with those versions, whose float32 channel statistics rounded where these are exact: 0.35% of pixels one level
apart, benchmarks/README.md).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from vtr.runtime.frame import Frame, as_frame
from vtr.runtime.preprocess import clip_ufunc, planar_levels

#: Floor on a channel's standard deviation (0..255): a flat channel is shifted, not stretched.
_STD_FLOOR = 2.0
_HALF, _LOW, _HIGH = np.float32(0.5), np.float32(0.0), np.float32(255.0)


@functools.cache
def _ones(n: int) -> np.ndarray:
    return np.ones(n, dtype=np.float32)


@functools.cache
def _ramp_axis(width: int) -> tuple[np.ndarray, np.float32]:
    """x from -1 to 1 across the columns, and sum(x * x)."""
    x = np.linspace(-1.0, 1.0, width, dtype=np.float32)
    return x, (x * x).sum()


def _planar_column_means(p: np.ndarray) -> np.ndarray:
    """(W,) mean brightness of each column of planar (3, H, W) levels (all rows and channels)."""
    c, h, w = p.shape
    # the column sums are integers below 2**24: exact in float32 whatever BLAS's order
    return (_ones(c * h) @ p.reshape(c * h, w)) / np.float32(c) / np.float32(h)


def _planar_stats(p: np.ndarray, scratch: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel mean and (floored) standard deviation of planar (3, H, W) levels, float32 (3,) each.
    ``scratch``: a float32 array of p's shape for the squares (else one is allocated).

    Exact sums: each column's sum of levels and of squared levels is an integer below 2**24 for up to 258
    rows, so float32 holds it whatever BLAS's order, and the columns are added in float64."""
    c, h, w = p.shape
    ones = _ones(h)
    n = float(h * w)
    # np.add.reduce: what ndarray.sum runs, without its two Python wrappers
    mean = np.add.reduce(np.matmul(ones, p), axis=1, dtype=np.float64) / n
    squares = np.multiply(p, p, out=scratch)
    var = np.maximum(np.add.reduce(np.matmul(ones, squares), axis=1, dtype=np.float64) / n - mean * mean, 0.0)
    std = np.maximum(np.sqrt(var), _STD_FLOOR)
    return mean.astype(np.float32), std.astype(np.float32)


def channel_stats(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel mean and standard deviation of a uint8 (H, W, 3) image, float32 (3,) each."""
    return _planar_stats(planar_levels(image))


def _column_means(image: np.ndarray) -> np.ndarray:
    """(W,) mean brightness of each image column (all rows and channels)."""
    return _planar_column_means(planar_levels(image))


def _clip_floor(p: np.ndarray) -> np.ndarray:
    """In place: clipped to 0..255 and floored, i.e. the uint8 conversion (after a + 0.5), kept in float32."""
    clip_ufunc(p, _LOW, _HIGH, out=p)
    return np.floor(p, out=p)


def _ramp_gain(p: np.ndarray, ref_cols: np.ndarray) -> np.ndarray:
    """(W,) gain exp(b x) removing the linear trend of log(ref_cols / cols) ("+ 1"s included)."""
    x, xx = _ramp_axis(p.shape[2])
    log_ratio = np.log(ref_cols / (_planar_column_means(p) + np.float32(1.0)))
    # np.add.reduce / n: what ndarray.mean and .sum compute, without their Python-level wrappers
    log_ratio -= np.add.reduce(log_ratio) / np.float32(log_ratio.size)
    slope = float(np.add.reduce(x * log_ratio) / xx)
    return np.exp(slope * x)


# Every operation on the image below is one contiguous pass over C-ordered planes, in place in reused
# buffers: per-plane values are scalars, per-column gains a row broadcast (an interleaved (H, W, 3) layout
# made numpy's inner loops 3 elements long).
def _ramp(levels: np.ndarray, ref_cols: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``levels`` with the side ramp removed, into ``out`` (a new array if None)."""
    # one gain per column: broadcast along rows of W values
    p = np.multiply(levels, _ramp_gain(levels, ref_cols), out=out)
    p += _HALF
    return _clip_floor(p)


def _stats_in_place(
    p: np.ndarray, ref_mean: np.ndarray, ref_std: np.ndarray, scratch: np.ndarray | None = None
) -> np.ndarray:
    mean, std = _planar_stats(p, scratch)
    gain = ref_std / std
    p *= gain[:, None, None]  # one scalar per plane: numpy's fast contiguous loop
    p += (ref_mean - mean * gain + _HALF)[:, None, None]
    return _clip_floor(p)


def _to_uint8(p: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(p.transpose(1, 2, 0)).astype(np.uint8)


def match_statistics(
    image: np.ndarray, reference: np.ndarray, reference_stats: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """``image`` (uint8 (H, W, 3)) with each channel's mean and spread set to ``reference``'s; uint8."""
    if image.dtype != np.uint8 or reference.dtype != np.uint8 or image.shape[-1] != reference.shape[-1]:
        raise ValueError(
            f"expected two uint8 RGB images, got {image.dtype} {image.shape} and {reference.dtype} "
            f"{reference.shape}"
        )
    ref_mean, ref_std = reference_stats if reference_stats is not None else channel_stats(reference)
    return _to_uint8(_stats_in_place(planar_levels(image).copy(), ref_mean, ref_std))


def remove_side_ramp(
    image: np.ndarray, reference: np.ndarray, reference_cols: np.ndarray | None = None
) -> np.ndarray:
    """``image`` times a left-to-right gain exp(b x) (x from -1 to 1) that removes the linear trend of
    log(reference / image) column brightness: one side of the view lit differently (a lamp off). The mean
    gain is left to :func:`match_statistics`; a trend that geometry made (a nearer wall on one side) is
    partly removed too, which costs little on clean views (about 2 levels of mean change on 0..255)."""
    ref_cols = reference_cols if reference_cols is not None else _column_means(reference)
    return _to_uint8(_ramp(planar_levels(image), ref_cols + np.float32(1.0)))


@dataclass(frozen=True)
class LightReference:
    """What light matching needs of one subgoal, computed once per subgoal: its channel statistics and
    its column means (+ 1, as the ramp's log ratio takes them)."""

    mean: np.ndarray
    std: np.ndarray
    cols: np.ndarray

    @classmethod
    def of(cls, subgoal: Frame | np.ndarray) -> LightReference:
        p = planar_levels(subgoal)
        mean, std = _planar_stats(p)
        return cls(mean, std, _planar_column_means(p) + np.float32(1.0))


def matched_planar(
    current: Frame | np.ndarray,
    reference: LightReference,
    side_ramp: bool = True,
    out: np.ndarray | None = None,
    scratch: np.ndarray | None = None,
) -> np.ndarray:
    """float32 (3, H, W): ``current`` (a frame, or uint8 (H, W, 3)) recoloured to ``reference``, in 0..255
    levels: the values of ``match_statistics(remove_side_ramp(current))``, planar and in float32. ``out`` and
    ``scratch`` (float32 (3, H, W)) are reused buffers; the result is ``out``."""
    levels = planar_levels(current)  # a frame's own levels: the controller's matcher used them already
    if side_ramp:
        p = _ramp(levels, reference.cols, out)
    elif out is None:
        p = levels.copy()
    else:
        p = out
        np.copyto(p, levels)
    return _stats_in_place(p, reference.mean, reference.std, scratch)


class LightMatchedPolicy:
    """A policy whose current image is recoloured to the subgoal's statistics before each prediction.

    Everything else (``image_shape``, ``meta``, ``nonfinite_count``, ``check_route``, timings) is the
    wrapped policy's. A subgoal's statistics are kept on its frame (:meth:`Frame.derived`); the recoloured
    image goes to the wrapped policy as a frame made from its planar float32 levels, which ``OnnxPolicy``
    scales into its input tensor without a uint8 round trip (another policy reads ``frame.image``).
    """

    def __init__(self, policy: Any, side_ramp: bool = True) -> None:
        self.policy, self.side_ramp = policy, side_ramp
        self._scratch: np.ndarray | None = None  # the squares of the channel statistics, reused

    def __getattr__(self, name: str) -> Any:
        return getattr(self.policy, name)

    def match(self, current: Frame | np.ndarray, subgoal: Frame | np.ndarray) -> np.ndarray:
        """float32 (3, H, W) levels of ``current`` recoloured to ``subgoal`` (see :func:`matched_planar`), in
        a new array the caller owns."""
        current, subgoal = as_frame(current), as_frame(subgoal)
        reference = subgoal.derived(LightReference, LightReference.of)
        shape = current.levels.shape
        if self._scratch is None or self._scratch.shape != shape:
            self._scratch = np.empty(shape, np.float32)
        return matched_planar(current, reference, self.side_ramp, np.empty(shape, np.float32), self._scratch)

    def predict(self, current: Frame | np.ndarray, subgoal: Frame | np.ndarray) -> np.ndarray:
        subgoal = as_frame(subgoal)
        return self.policy.predict(Frame.from_levels(self.match(current, subgoal)), subgoal)
