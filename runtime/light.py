"""Repeat-time light compensation for a policy trained on images lit as in the teach run.

The light between teach and repeat changes (evening, a lamp off); a network that has only seen the taught
light steers wrongly when the current image is darker, brighter or tinted. ``match_statistics`` moves the
current image's per-channel mean and standard deviation onto the subgoal's (the taught light), which
undoes any global gain, offset or colour cast, before the network sees the pair; ``remove_side_ramp``
first evens out a left-to-right gain (one side of the view darker). DVMPC recolours the same
way (there the subgoal towards the current image); we recolour the current image, so the network keeps
seeing images lit as in training. It leaves geometry alone: where things are in the image does not move.

``LightMatchedPolicy`` wraps any policy (``predict(current, subgoal)``) with it: the runtime's option
``vtr repeat --match-light``. A model trained with augmentation and ``STANDARDISED`` preprocessing needs
it less; it costs about 0.25 ms per step on 128x128 (1.4 ms before its
reductions went through BLAS; the condition-suite results were measured with that version, equal to float
rounding).
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Floor on a channel's standard deviation (0..255): a flat channel is shifted, not stretched.
_STD_FLOOR = 2.0


def _sums(x: np.ndarray) -> np.ndarray:
    """Column sums of a 2-D float32 array through BLAS (numpy's axis-0 reductions over a short inner axis
    are about 10x slower)."""
    return np.ones(x.shape[0], dtype=np.float32) @ x


def channel_stats(image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel mean and standard deviation of a uint8 (H, W, 3) image, float32 (3,) each."""
    x = image.reshape(-1, image.shape[-1]).astype(np.float32)
    n = np.float32(x.shape[0])
    mean = _sums(x) / n
    var = np.maximum(_sums(x * x) / n - mean * mean, 0)
    return mean, np.maximum(np.sqrt(var), np.float32(_STD_FLOOR))


def _column_means(image: np.ndarray) -> np.ndarray:
    """(W,) mean brightness of each image column (all rows and channels)."""
    h, w, c = image.shape
    return _sums(image.reshape(h, w * c).astype(np.float32)).reshape(w, c).mean(axis=1) / np.float32(h)


def match_statistics(
    image: np.ndarray, reference: np.ndarray, reference_stats: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """``image`` (uint8 (H, W, 3)) with each channel's mean and spread set to ``reference``'s; uint8."""
    if image.dtype != np.uint8 or reference.dtype != np.uint8 or image.shape[-1] != reference.shape[-1]:
        raise ValueError(f"expected two uint8 RGB images, got {image.dtype} {image.shape} and {reference.dtype} "
                         f"{reference.shape}")  # fmt: skip
    mean, std = channel_stats(image)
    ref_mean, ref_std = reference_stats if reference_stats is not None else channel_stats(reference)
    gain = ref_std / std
    # per-channel values repeated along a whole row: broadcasting a (3,) array makes numpy's inner loop
    # 3 elements long, 4x slower than one row of W * 3 (the same operations on the same values)
    w, c = image.shape[-2:]
    out = image.reshape(-1, w * c).astype(np.float32)
    out *= np.tile(gain, w)
    out += np.tile(ref_mean - mean * gain + np.float32(0.5), w)
    return np.clip(out, 0, 255, out=out).astype(np.uint8).reshape(image.shape)


def remove_side_ramp(
    image: np.ndarray, reference: np.ndarray, reference_cols: np.ndarray | None = None
) -> np.ndarray:
    """``image`` times a left-to-right gain exp(b x) (x from -1 to 1) that removes the linear trend of
    log(reference / image) column brightness: one side of the view lit differently (a lamp off). The mean
    gain is left to :func:`match_statistics`; a trend that geometry made (a nearer wall on one side) is
    partly removed too, which costs little on clean views (about 2 levels of mean change on 0..255)."""
    cols = _column_means(image) + 1.0
    ref_cols = (reference_cols if reference_cols is not None else _column_means(reference)) + 1.0
    x = np.linspace(-1.0, 1.0, image.shape[1], dtype=np.float32)
    log_ratio = np.log(ref_cols / cols)
    slope = float((x * (log_ratio - log_ratio.mean())).sum() / (x * x).sum())
    w, c = image.shape[-2:]
    out = image.reshape(-1, w * c).astype(np.float32)
    out *= np.repeat(np.exp(slope * x), c)  # one gain per column, repeated over its channels (see above)
    out += np.float32(0.5)
    return np.clip(out, 0, 255, out=out).astype(np.uint8).reshape(image.shape)


class LightMatchedPolicy:
    """A policy whose current image is recoloured to the subgoal's statistics before each prediction.

    Everything else (``image_shape``, ``meta``, ``nonfinite_count``, ``check_route``, timings) is the
    wrapped policy's. The subgoal's statistics are cached while the same subgoal array comes back.
    """

    def __init__(self, policy: Any, side_ramp: bool = True) -> None:
        self.policy, self.side_ramp = policy, side_ramp
        self._subgoal: np.ndarray | None = None
        self._stats: tuple[np.ndarray, np.ndarray] | None = None
        self._cols: np.ndarray | None = None

    def __getattr__(self, name: str) -> Any:
        return getattr(self.policy, name)

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        if subgoal is not self._subgoal or self._stats is None:
            self._subgoal, self._stats, self._cols = subgoal, channel_stats(subgoal), _column_means(subgoal)
        if self.side_ramp:
            current = remove_side_ramp(current, subgoal, self._cols)
        return self.policy.predict(match_statistics(current, subgoal, self._stats), subgoal)
