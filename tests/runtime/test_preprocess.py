"""The preprocessing and image error shared by training and the runtime."""

from __future__ import annotations

import numpy as np
import pytest

from vtr.runtime.preprocess import PREPROCESSINGS, image_error, to_nchw


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


def test_standardised_preprocessing_cancels_gain_offset_and_colour_cast():
    from vtr.runtime.preprocess import PREPROCESSING, STANDARDISED, normalise

    rng = np.random.default_rng(1)
    img = rng.integers(40, 180, (16, 16, 3), dtype=np.uint8)
    cast = np.clip(img * np.array([1.3, 1.0, 0.8]) + 10, 0, 255).astype(np.uint8)
    a, b = to_nchw(img, STANDARDISED), to_nchw(cast, STANDARDISED)
    np.testing.assert_allclose(a.mean(axis=(2, 3)), 0.0, atol=1e-5)
    np.testing.assert_allclose(a.std(axis=(2, 3)), 1.0, atol=0.01)  # eps in the variance
    assert np.abs(a - b).max() < 0.05  # only rounding to uint8 differs
    # the default is today's unit scaling, bit for bit
    assert to_nchw(img, PREPROCESSING).tobytes() == to_nchw(img).tobytes()
    assert normalise(a, PREPROCESSING) is a
    with pytest.raises(ValueError, match="unknown preprocessing"):
        to_nchw(img, "bgr_minus_mean")


def test_training_applies_the_very_same_normalisation():
    torch = pytest.importorskip("torch")  # third-party: the runtime test run may lack torch
    from vtr.runtime.preprocess import STANDARDISED, normalise

    rng = np.random.default_rng(2)
    x = to_nchw(rng.integers(0, 256, (3, 8, 8, 3), dtype=np.uint8))
    np.testing.assert_allclose(
        normalise(torch.from_numpy(x), STANDARDISED).numpy(), normalise(x, STANDARDISED), atol=1e-6
    )


def test_model_meta_names_a_known_preprocessing():
    from vtr.runtime.model_meta import ModelMeta
    from vtr.runtime.preprocess import STANDARDISED

    assert ModelMeta(preprocessing=STANDARDISED).preprocessing == STANDARDISED
    with pytest.raises(ValueError, match="unknown preprocessing"):
        ModelMeta(preprocessing="bgr_minus_mean")


def test_planar_levels_are_a_frames_own_and_an_arrays_made_anew():
    from vtr.runtime.frame import as_frame
    from vtr.runtime.preprocess import planar_levels

    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, (8, 12, 3), dtype=np.uint8)
    levels = planar_levels(image)
    assert levels.dtype == np.float32 and levels.flags.c_contiguous and not levels.flags.writeable
    assert np.array_equal(levels, image.transpose(2, 0, 1))
    image[0, 0] = 7  # an array may change in place: its levels are made from it as it is now
    assert planar_levels(image)[:, 0, 0].tolist() == [7, 7, 7]
    frame = as_frame(image)
    assert planar_levels(frame) is planar_levels(frame) is frame.levels  # made once, kept on the frame
    image[0, 0] = 9  # the frame owns its pixels: a change to the array it came from does not reach it
    assert planar_levels(frame)[:, 0, 0].tolist() == [7, 7, 7] and frame.image[0, 0].tolist() == [7, 7, 7]
    with pytest.raises(ValueError, match="uint8"):
        planar_levels(image.astype(np.float32))


@pytest.mark.parametrize("preprocessing", PREPROCESSINGS)
def test_input_into_gives_to_nchws_tensor(preprocessing):
    from vtr.runtime.preprocess import input_into, planar_levels

    image = np.random.default_rng(2).integers(0, 256, (16, 8, 3), dtype=np.uint8)
    expected = to_nchw(image, preprocessing)
    buffer = np.empty((3, 16, 8), np.float32)
    tensor = input_into(planar_levels(image), buffer, preprocessing)
    assert (
        tensor.shape == (1, 3, 16, 8)
        and np.array_equal(tensor, expected)
        and np.shares_memory(tensor, buffer)
    )


def test_numpy_standardisation_in_place_equals_the_formula_bit_for_bit():
    from vtr.runtime.preprocess import STANDARDISED, normalise

    x = to_nchw(np.random.default_rng(3).integers(0, 256, (2, 24, 40, 3), dtype=np.uint8))
    centred = x - x.mean(axis=(-2, -1), keepdims=True)
    formula = centred / ((centred * centred).mean(axis=(-2, -1), keepdims=True) + 1e-4) ** 0.5
    copy = normalise(x, STANDARDISED)
    assert copy is not x and np.array_equal(copy, formula)
    strided = x.transpose(
        0, 1, 3, 2
    )  # not C-ordered: standardised on a copy (sums in its order), never in place
    out = normalise(strided, STANDARDISED, in_place=True)
    assert not np.shares_memory(out, x)
    np.testing.assert_allclose(out, formula.transpose(0, 1, 3, 2), atol=1e-6)
    assert normalise(x, STANDARDISED, in_place=True) is x and np.array_equal(x, formula)
