"""The camera mapping (runtime/resample.py): centre crop to the model's aspect, box-filter (bilinear upwards)
resampling, exact on integer factors, and the field of view the crop leaves."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtr.runtime.contracts import CameraSpec
from vtr.runtime.resample import cropped_fov, plan

RNG = np.random.default_rng(0)


def _image(w: int, h: int) -> np.ndarray:
    return RNG.integers(0, 256, (h, w, 3), dtype=np.uint8)


@pytest.mark.parametrize(("w", "h"), [(256, 256), (512, 384), (1024, 1024), (384, 512)])
def test_integer_factors_are_the_exact_block_mean(w, h):
    mapping = plan(CameraSpec(w, h, 90.0, 0.3), (128, 128))
    image = _image(w, h)
    x, y, cw, ch = (int(v) for v in mapping.crop)
    k = cw // 128
    block = image[y : y + ch, x : x + cw].reshape(128, k, 128, k, 3).astype(np.float64).mean(axis=(1, 3))
    np.testing.assert_array_equal(mapping(image), np.floor(block + 0.5).astype(np.uint8))


def test_a_non_integer_factor_averages_each_output_pixels_area():
    mapping = plan(CameraSpec(640, 480, 90.0, 0.3), (128, 128))  # the centre 480x480, 3.75 pixels each
    image = _image(640, 480)
    # an independent reference: every pixel split in 4x4 makes each output pixel a block of 15x15
    fine = np.repeat(np.repeat(image[:, 80:560].astype(np.float64), 4, axis=0), 4, axis=1)
    ref = fine.reshape(128, 15, 128, 15, 3).mean(axis=(1, 3))
    out = mapping(image).astype(np.float64)
    assert np.abs(out - ref).max() <= 0.5 + 1e-3  # rounding only


def test_upsampling_is_bilinear_and_flat_stays_flat():
    mapping = plan(CameraSpec(160, 120, 90.0, 0.3), (128, 128))
    assert mapping.crop == (20.0, 0.0, 120.0, 120.0)
    flat = np.full((120, 160, 3), 200, np.uint8)
    assert (mapping(flat) == 200).all()
    ramp = np.broadcast_to(np.arange(160, dtype=np.uint8)[None, :, None], (120, 160, 3)).copy()
    row = mapping(ramp)[64, :, 0].astype(int)
    assert row[0] == 20 and row[-1] == 139 and (np.diff(row) >= 0).all()  # only the crop, monotone


def test_the_crop_keeps_the_model_aspect_and_the_centre():
    image = np.zeros((120, 160, 3), np.uint8)
    image[:, :20] = image[:, 140:] = 255  # what the square crop leaves out
    out = plan(CameraSpec(160, 120, 90.0, 0.3), (128, 128))(image)
    assert out.max() == 0
    tall = plan(CameraSpec(120, 160, 90.0, 0.3), (128, 128))
    assert tall.crop == (0.0, 20.0, 120.0, 120.0) and tall.seen_fov_deg == pytest.approx(90.0)
    wide_model = plan(CameraSpec(640, 480, 90.0, 0.3), (96, 128))  # a 4:3 model takes all of a 4:3 camera
    assert wide_model.crop == (0.0, 0.0, 640.0, 480.0) and wide_model.seen_fov_deg == pytest.approx(90.0)


def test_the_field_of_view_after_the_crop():
    assert cropped_fov(90.0, 120 / 160) == pytest.approx(2 * math.degrees(math.atan(0.75)))  # 73.74
    assert plan(CameraSpec(160, 120, 90.0, 0.3), (128, 128)).seen_fov_deg == pytest.approx(73.7398, abs=1e-4)
    four_three = 2 * math.degrees(math.atan(4 / 3))  # 106.26: a 4:3 camera whose square centre sees 90
    assert plan(CameraSpec(320, 240, four_three, 0.3), (128, 128)).seen_fov_deg == pytest.approx(90.0)
    assert plan(CameraSpec(160, 120, None, 0.3), (128, 128)).seen_fov_deg is None  # unknown stays unknown


def test_a_camera_wider_than_the_model_is_cropped_further_to_the_widest_it_saw():
    mapping = plan(CameraSpec(640, 480, 130.0, 0.3), (128, 128), widest_deg=90.0, tolerance_deg=2.0)
    assert mapping.narrowed and mapping.seen_fov_deg == pytest.approx(90.0)
    cw = 640 * math.tan(math.radians(45)) / math.tan(math.radians(65))
    assert mapping.crop == pytest.approx(((640 - cw) / 2, (480 - cw) / 2, cw, cw))
    assert "cropped further" in mapping.narrowing() and "\n" not in mapping.narrowing()
    within = plan(CameraSpec(128, 128, 91.5, 0.3), (128, 128), widest_deg=90.0, tolerance_deg=2.0)
    assert within.identity and not within.narrowed  # inside the tolerance: untouched
    narrower = plan(CameraSpec(160, 120, 60.0, 0.3), (128, 128), widest_deg=90.0, tolerance_deg=2.0)
    assert not narrower.narrowed and narrower.seen_fov_deg < 60  # never widened: the check refuses it


def test_the_models_own_camera_passes_through_untouched():
    mapping = plan(CameraSpec(128, 128, 90.0, 0.3), (128, 128), widest_deg=90.0)
    image = _image(128, 128)
    assert mapping.identity and mapping(image) is image
    frame = plan(CameraSpec(160, 120, 90.0, 0.3), (128, 128)).frame(_image(160, 120))
    assert frame.shape == (128, 128, 3) and not frame.image.flags.writeable
