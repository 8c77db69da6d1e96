"""The one preprocessing function shared by training and the runtime, so the two can never drift."""

from __future__ import annotations

import numpy as np

#: Name stored in the ONNX metadata; the runtime refuses a model that expects anything else.
PREPROCESSING = "rgb8_hwc_to_float32_nchw_div255"


def to_nchw(images: np.ndarray) -> np.ndarray:
    """uint8 RGB images (H, W, 3) or (B, H, W, 3) -> float32 (B, 3, H, W) in [0, 1]."""
    if images.dtype != np.uint8:
        raise ValueError(f"expected uint8 RGB images, got dtype {images.dtype}")
    if images.ndim == 3:
        images = images[None]
    if images.ndim != 4 or images.shape[-1] != 3:
        raise ValueError(f"expected (H, W, 3) or (B, H, W, 3) RGB images, got shape {images.shape}")
    out = images.transpose(0, 3, 1, 2).astype(np.float32)
    out *= np.float32(1.0 / 255.0)
    return out


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
