"""The one preprocessing shared by training and the runtime, so the two can never drift.

A model names its preprocessing in its metadata (``ModelMeta.preprocessing``, from
``VelocityNetConfig.preprocessing`` at training time); the runtime applies exactly that one:

- ``PREPROCESSING`` (the default, every model shipped so far): uint8 / 255, so pixels are in [0, 1];
- ``STANDARDISED``: then each image's each colour channel shifted and scaled to zero mean and unit
  variance, so a global change of brightness, contrast or colour balance between teach and repeat does
  not reach the network (the runtime counterpart of DVMPC recolouring the subgoal to the current image).

``normalise`` is written once for numpy arrays and torch tensors alike (only ``mean(axis=, keepdims=)``
and arithmetic), so training calls the very function the runtime does.
"""

from __future__ import annotations

from typing import Any, TypeVar

import numpy as np

from vtr.runtime.frame import Frame, as_frame

#: Unit scaling: the default, and the name stored in every model shipped so far.
PREPROCESSING = "rgb8_hwc_to_float32_nchw_div255"
#: Unit scaling, then per-image, per-channel zero mean and unit variance.
STANDARDISED = "rgb8_hwc_to_float32_nchw_div255_channel_standardised"
#: Every preprocessing this runtime can apply; a model naming another one is refused.
PREPROCESSINGS = (PREPROCESSING, STANDARDISED)
#: Added to the variance: a flat channel (all one colour) stays finite.
_EPS = 1e-4
#: uint8 levels -> [0, 1], as float32 (the one factor every path multiplies by).
_SCALE = np.float32(1.0 / 255.0)
#: numpy's clip ufunc itself, for the control step: ``np.clip`` and ``ndarray.clip`` reach it through
#: Python wrappers (~1.3 us a call). The same function on the same values, so the same results.
clip_ufunc = getattr(getattr(np, "_core", None), "umath", np).clip

ArrayT = TypeVar("ArrayT", bound=Any)


def check_preprocessing(name: str) -> str:
    if name not in PREPROCESSINGS:
        raise ValueError(f"unknown preprocessing {name!r}; this runtime knows {', '.join(PREPROCESSINGS)}")
    return name


def normalise(x: ArrayT, preprocessing: str, in_place: bool = False) -> ArrayT:
    """float (..., 3, H, W) in [0, 1] (numpy or torch) -> the network's input for ``preprocessing``.

    Numpy arrays take the same formula plane by plane, in place with one temporary instead of three (the
    runtime pays it every step); ``in_place`` (numpy only) overwrites ``x``, a C-ordered float array the
    caller owns."""
    if check_preprocessing(preprocessing) == PREPROCESSING:
        return x
    if isinstance(x, np.ndarray):
        return _standardise_planes(x if in_place and x.flags.c_contiguous else np.array(x, order="C"))
    centred = x - x.mean(axis=(-2, -1), keepdims=True)
    return centred / ((centred * centred).mean(axis=(-2, -1), keepdims=True) + _EPS) ** 0.5


def _standardise_planes(x: np.ndarray) -> np.ndarray:
    """In place: each (H, W) plane of C-ordered ``x`` to zero mean and unit variance (``_EPS`` added);
    pairwise sums along each plane, as accurate as the axis means (2e-7 of float64 at 128x128)."""
    planes = x.reshape(-1, x.shape[-2] * x.shape[-1])  # a view: x is C-ordered
    n = planes.shape[1]
    mean = np.add.reduce(planes, axis=1)
    mean /= n
    planes -= mean[:, None]
    var = np.add.reduce(planes * planes, axis=1)
    var /= n
    var += _EPS
    planes /= np.sqrt(var)[:, None]
    return x


def to_nchw(images: np.ndarray, preprocessing: str = PREPROCESSING) -> np.ndarray:
    """uint8 RGB images (H, W, 3) or (B, H, W, 3) -> float32 (B, 3, H, W): in [0, 1], then ``normalise``d
    (:func:`input_into` of their levels: the runtime's one encoder)."""
    if images.dtype != np.uint8:
        raise ValueError(f"expected uint8 RGB images, got dtype {images.dtype}")
    if images.ndim == 3:
        images = images[None]
    if images.ndim != 4 or images.shape[-1] != 3:
        raise ValueError(f"expected (H, W, 3) or (B, H, W, 3) RGB images, got shape {images.shape}")
    # C order: onnxruntime copies a tensor that is not contiguous on every run (about 13 us at 128x128)
    levels = images.transpose(0, 3, 1, 2).astype(np.float32, order="C")
    return input_into(levels, levels, preprocessing)


def planar_levels(image: Frame | np.ndarray) -> np.ndarray:
    """uint8 (H, W, 3) image or :class:`~vtr.runtime.frame.Frame` -> read-only float32 (3, H, W) of the same
    values, C order: a Frame's own levels (made once per frame), else those of the checked array."""
    return as_frame(image).levels


def input_into(levels: np.ndarray, out: np.ndarray, preprocessing: str = PREPROCESSING) -> np.ndarray:
    """float32 (3, H, W) or (B, 3, H, W) holding uint8 levels (a Frame's) -> the network's (B, 3, H, W) input,
    written into ``out`` (float32 of the same shape, C order; ``levels`` itself will do): the one encoder of
    images for the network, ``to_nchw``'s and the policy's (uint8 / 255, then ``normalise`` in place)."""
    np.multiply(levels, _SCALE, out=out)
    return normalise(out.reshape(-1, *out.shape[-3:]), preprocessing, in_place=True)


def image_error(a: np.ndarray, b: np.ndarray) -> float:
    """Mean absolute pixel difference on the 0..255 scale (the paper's |I_t - I_i| against e_m)."""
    if a.shape != b.shape:
        raise ValueError(f"image shapes differ: {a.shape} vs {b.shape}")
    if a.dtype != np.uint8 or b.dtype != np.uint8:
        raise ValueError(f"expected uint8 images, got {a.dtype} and {b.dtype}")
    # |a - b| in uint8 without widening copies (2.4x faster than the int16 route on 128x128x3);
    # a uint32 sum cannot overflow below 16.8 M pixels.
    diff = np.maximum(a, b)
    diff -= np.minimum(a, b)
    return float(diff.sum(dtype=np.uint32)) / diff.size
