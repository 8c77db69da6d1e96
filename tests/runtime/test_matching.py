"""Patch-normalised matching: blind to light, robust to a changed region, still sensitive to motion."""

from __future__ import annotations

import numpy as np
import pytest
from texture_views import lit, view

from vtr.runtime.matching import MatchConfig, Matcher
from vtr.runtime.preprocess import image_error


def test_raw_is_the_papers_image_error():
    m = Matcher(MatchConfig.paper())
    a, b = view(0), view(5)
    assert m.image_distance(a, b) == image_error(a, b)
    np.testing.assert_allclose(m.distances(a, np.stack([a, b])), [0.0, image_error(a, b)])


@pytest.mark.parametrize("gain, offset", [(0.6, 0.0), (1.3, 0.0), ((1.2, 1.0, 0.75), 0.0), (1.5, -50.0)])
def test_patch_distance_ignores_brightness_contrast_and_colour_cast(gain, offset):
    m, raw = Matcher(), Matcher(MatchConfig.paper())
    a = lit(view(100), 0.7, 30)  # mid-range, so the changed light does not clip
    changed = lit(a, gain, offset)
    moved = view(104)
    assert raw.image_distance(a, changed) > 10  # the paper's error moves a lot
    assert m.image_distance(a, changed) < 0.1 * m.image_distance(a, moved)


def test_patch_distance_grows_with_motion():
    m = Matcher()
    d = [m.image_distance(view(100), view(100 + s)) for s in (0, 1, 2, 4, 8)]
    assert d[0] == 0.0 and all(np.diff(d) > 0)


def test_one_side_darker_is_almost_invisible():
    m = Matcher()
    ramp = np.linspace(0.45, 1.0, 64, dtype=np.float32)[None, :, None]
    a = view(50)
    assert m.image_distance(a, lit(a, ramp)) < 0.3 * m.image_distance(a, view(52))


def test_median_over_tiles_ignores_a_changed_quarter():
    a = view(200)
    changed = a.copy()
    changed[:32, :32] = view(0)[:32, :32]  # a quarter of the view re-textured
    median, mean = Matcher(MatchConfig(trim=0.5)), Matcher(MatchConfig(trim=0.0))
    assert median.image_distance(a, changed) == pytest.approx(0.0, abs=1e-6)
    assert mean.image_distance(a, changed) > 0.1


def test_features_batch_matches_single_and_validates():
    m = Matcher()
    batch = np.stack([view(0), view(9)])
    np.testing.assert_allclose(m.features(batch)[1], m.features(view(9)), rtol=1e-6)
    with pytest.raises(ValueError, match="multiple"):
        m.features(np.zeros((20, 20, 3), np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        m.features(np.zeros((64, 64, 3), np.float32))


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"method": "sift"}, "method"),
        ({"trim": 1.0}, "trim"),
        ({"patch": 1}, "patch"),
        ({"std_floor": 0}, "std_floor"),
    ],
)
def test_match_config_validation(kwargs, fragment):
    with pytest.raises(ValueError, match=fragment):
        MatchConfig(**kwargs)


def test_raw_distances_over_a_stack_are_each_images_image_error_to_the_bit():
    rng = np.random.default_rng(3)
    m = Matcher(MatchConfig.paper())
    image = rng.integers(0, 256, (16, 24, 3), dtype=np.uint8)
    others = rng.integers(0, 256, (6, 16, 24, 3), dtype=np.uint8)
    others[2] = image  # a distance of 0
    got = m.distances(image, others)
    assert got.dtype == np.float64 and got[2] == 0.0
    assert np.array_equal(got, [image_error(image, o) for o in others])
    assert m.distances(image, others[:0]).shape == (0,)
    with pytest.raises(ValueError, match="image shapes differ"):
        m.distances(image, others[:, :8])


def test_shifted_features_line_a_turned_view_up_with_the_taught_tiles_it_faces():
    """A view whose content moved ``shift`` pooled pixels sideways (a robot turned off the taught heading),
    cut ``shift`` to the right, gives the taught view's own features for every tile it faces."""
    from vtr.runtime.frame import as_frame

    m = Matcher(MatchConfig())
    shifts = (3, -3, 6, -6)
    taught = np.random.default_rng(5).integers(0, 256, (64, 64, 3), dtype=np.uint8)
    grid = m.features(taught).reshape(4, 4, -1)  # 4 x 4 tiles of 8 pooled pixels
    stack = m.features(np.stack([taught, np.roll(taught, 2, axis=0)]))
    for i, shift in enumerate(shifts):
        turned = as_frame(np.roll(taught, 2 * shift, axis=1))  # 2 image pixels a pooled pixel
        feats = m.shifted_features(turned, shifts)
        assert feats.shape == (4, 4, 3, grid.shape[-1])
        faced = grid[:, :3] if shift > 0 else grid[:, 1:]  # the edge column the shift leaves half outside
        assert np.allclose(feats[i], faced, atol=1e-5)
        assert m.distance(m.features(turned), m.features(taught)) > 0.8  # unshifted: unrelated
        got = m.shifted_distances(turned, shifts, stack)
        assert got.shape == (4, 2) and got[i, 0] < 1e-5 and (np.delete(got[:, 0], i) > 0.5).all()
        assert np.isclose(got[i, 1], m.distances(feats[i].reshape(12, -1), stack[1:, faced_index(shift)])[0])
        only = m.shifted_distances(turned, shifts, stack, i)
        assert np.array_equal(only[i], got[i]) and np.isnan(np.delete(only, i, axis=0)).all()
    with pytest.raises(ValueError, match="shift"):
        m.shifted_features(as_frame(taught), (8,))


def faced_index(shift: int) -> np.ndarray:
    """The taught tiles (of a 4 x 4 grid) that a view cut ``shift`` across faces."""
    first = 0 if shift > 0 else 1
    return (np.arange(4)[:, None] * 4 + np.arange(first, first + 3)[None, :]).ravel()
