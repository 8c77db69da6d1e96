"""Repeat-time light compensation: the current image recoloured to the subgoal's light."""

from __future__ import annotations

import numpy as np
import pytest
from texture_views import lit, view

from vtr.runtime.light import LightMatchedPolicy, channel_stats, match_statistics
from vtr.runtime.preprocess import PREPROCESSINGS


@pytest.mark.parametrize("gain, offset", [(0.7, 0.0), (1.3, 0.0), ((1.2, 1.0, 0.75), 0.0), (0.8, 25.0)])
def test_a_global_light_change_is_undone(gain, offset):
    taught = lit(view(40), 0.6, 40)  # mid-range: the changed light does not clip
    changed = lit(taught, gain, offset)
    restored = match_statistics(changed, taught)
    assert np.abs(restored.astype(int) - taught.astype(int)).mean() < 1.5
    assert np.abs(changed.astype(int) - taught.astype(int)).mean() > 8


def test_geometry_is_left_alone():
    a, b = view(0), view(30)
    out = match_statistics(b, a)
    # recolouring b cannot make it look like a: the pattern stays b's
    corr = np.corrcoef(out[..., 0].ravel(), b[..., 0].ravel())[0, 1]
    assert corr > 0.99
    with pytest.raises(ValueError, match="uint8"):
        match_statistics(b.astype(np.float32), a)


class Recorder:
    image_shape = (64, 64)
    nonfinite_count = 3

    def __init__(self) -> None:
        self.seen: list[np.ndarray] = []

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        self.seen.append(np.asarray(current))  # a frame: the repeat loop's policies get frames
        return np.zeros((2, 2), np.float32)


def test_the_wrapper_recolours_the_current_image_only_and_passes_the_rest_through():
    inner = Recorder()
    policy = LightMatchedPolicy(inner)
    taught = lit(view(10), 0.6, 40)
    policy.predict(lit(taught, 0.7), taught)
    assert np.abs(inner.seen[0].astype(int) - taught.astype(int)).mean() < 1.5
    assert policy.image_shape == (64, 64) and policy.nonfinite_count == 3


def test_one_side_darker_is_evened_out_before_the_statistics_are_matched():
    from vtr.runtime.light import remove_side_ramp

    taught = lit(view(70), 0.6, 40)
    ramp = np.linspace(0.45, 1.0, 64, dtype=np.float32)[None, :, None]
    darker = lit(taught, ramp)
    only_stats = match_statistics(darker, taught)
    both = match_statistics(remove_side_ramp(darker, taught), taught)
    err = lambda a: np.abs(a.astype(int) - taught.astype(int)).mean()  # noqa: E731
    assert err(both) < 0.5 * err(only_stats) and err(both) < 4


@pytest.mark.parametrize("preprocessing", PREPROCESSINGS)
def test_an_onnx_policy_gets_the_recoloured_image_as_its_tensor_with_the_uint8_paths_values(
    tmp_path, preprocessing
):
    from vtr.benchmarks.standin import make_standin_velocitynet
    from vtr.runtime.light import remove_side_ramp
    from vtr.runtime.model_meta import ModelMeta
    from vtr.runtime.policy import OnnxPolicy

    meta = ModelMeta(image_height=64, image_width=64, horizon=2, preprocessing=preprocessing)
    policy = OnnxPolicy(make_standin_velocitynet(tmp_path / "m.onnx", meta=meta, widths=(4, 8, 8)))
    wrapped = LightMatchedPolicy(policy)
    for k, (gain, offset) in enumerate([(0.7, 10.0), ((1.2, 1.0, 0.75), -20.0), (1.0, 0.0)]):
        taught = lit(view(20 * k), 0.6, 40)
        ramp = np.linspace(0.5, 1.2, 64, dtype=np.float32)[None, :, None]
        current = lit(view(20 * k + 3), np.asarray(gain, np.float32) * ramp, offset)
        expected = policy.predict(match_statistics(remove_side_ramp(current, taught), taught), taught)
        assert np.array_equal(wrapped.predict(current, taught), expected)  # bit for bit, no uint8 round trip
        assert np.array_equal(
            LightMatchedPolicy(Recorder()).match(current, taught), wrapped.match(current, taught)
        )


def test_channel_statistics_are_exact_sums():
    rng = np.random.default_rng(5)
    for h, w in [(64, 64), (128, 128), (7, 33)]:
        image = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        image[: h // 2] //= 4  # a wide spread: float32 sums of squares in the wrong order drift here
        mean, std = channel_stats(image)
        x = image.reshape(-1, 3).astype(np.float64)
        np.testing.assert_allclose(mean, x.mean(axis=0), rtol=1e-7)
        np.testing.assert_allclose(std, np.maximum(x.std(axis=0), 2.0), rtol=1e-6)
