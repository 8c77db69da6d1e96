"""The preprocessing and image error shared by training and the runtime."""

from __future__ import annotations

import numpy as np
import pytest

from vtr.runtime.preprocess import image_error, to_nchw


def test_image_error_is_the_mean_absolute_difference_on_the_255_scale():
    rng = np.random.default_rng(0)
    a = rng.integers(0, 256, (32, 48, 3), dtype=np.uint8)
    b = rng.integers(0, 256, (32, 48, 3), dtype=np.uint8)
    reference = np.abs(a.astype(np.int64) - b.astype(np.int64)).mean()
    assert image_error(a, b) == pytest.approx(reference)
    assert image_error(a, b) == image_error(b, a)
    black, white = np.zeros((4, 4, 3), np.uint8), np.full((4, 4, 3), 255, np.uint8)
    assert image_error(black, white) == 255.0  # no uint8 wrap-around
    assert image_error(a, a) == 0.0


def test_image_error_leaves_its_inputs_alone_and_refuses_mismatches():
    a = np.full((4, 4, 3), 200, np.uint8)
    b = np.full((4, 4, 3), 50, np.uint8)
    assert image_error(a, b) == 150.0
    assert a[0, 0, 0] == 200 and b[0, 0, 0] == 50
    with pytest.raises(ValueError, match="shapes differ"):
        image_error(a, b[:2])
    with pytest.raises(ValueError, match="uint8"):
        image_error(a.astype(np.float32), b)


def test_to_nchw_scales_and_transposes():
    img = np.zeros((2, 3, 3), np.uint8)
    img[1, 2] = (255, 0, 51)
    out = to_nchw(img)
    assert out.shape == (1, 3, 2, 3) and out.dtype == np.float32
    np.testing.assert_allclose(out[0, :, 1, 2], [1.0, 0.0, 0.2], rtol=1e-6)
    assert to_nchw(np.stack([img, img])).shape == (2, 3, 2, 3)
    with pytest.raises(ValueError, match="uint8"):
        to_nchw(img.astype(np.float32))
    with pytest.raises(ValueError, match="RGB"):
        to_nchw(np.zeros((2, 3, 4), np.uint8))
