"""Camera views for matching tests: 64x64 windows into one wide smooth random texture, so shifting the
window by a few pixels is a small motion and its distance grows with the shift."""

from __future__ import annotations

import numpy as np


def _smooth_texture(h: int, w: int, k: int = 15, seed: int = 3) -> np.ndarray:
    """Random texture box-blurred over k pixels, folded through a sine into contrasty bands."""
    noise = np.random.default_rng(seed).random((h + k, w + k, 3))
    c = noise.cumsum(0).cumsum(1)
    box = c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]
    box = (box - box.min()) / (box.max() - box.min())
    return (127.5 + 115 * np.sin(12 * box[:h, :w])).astype(np.uint8)


STRIP = _smooth_texture(64, 600)


def view(x: int) -> np.ndarray:
    """(64, 64, 3) uint8 window starting at column x."""
    return np.ascontiguousarray(STRIP[:, x : x + 64])


def lit(image: np.ndarray, gain, offset: float = 0.0) -> np.ndarray:
    """Changed light: gain (scalar, per channel or per column) and offset, clipped to uint8."""
    return np.clip(image.astype(np.float32) * np.asarray(gain, np.float32) + offset, 0, 255).astype(np.uint8)
