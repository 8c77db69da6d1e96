"""OnnxPolicy: checks at load, stage timing, non-finite outputs never reach the robot."""

from __future__ import annotations

import numpy as np
import pytest
from runtime_fakes import H, W, build_velocitynet_onnx, corridor_route, render

from vtr.runtime.frame import Frame, as_frame
from vtr.runtime.policy import ModelMismatchError, OnnxPolicy
from vtr.runtime.preprocess import to_nchw


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    return build_velocitynet_onnx(str(tmp_path_factory.mktemp("m") / "tiny.onnx"))


def test_predict_shape_direction_and_stage_timing(model_path):
    policy = OnnxPolicy(model_path)
    assert policy.meta.horizon == 2 and policy.image_shape == (H, W)
    ahead = policy.predict(render(0.0), render(0.1))
    behind = policy.predict(render(0.1), render(0.0))
    assert ahead.shape == (2, 2) and ahead.dtype == np.float32
    assert ahead[0, 0] > 0.1 and behind[0, 0] < -0.1 and ahead[1, 0] == 0.0
    assert np.all(np.abs(ahead) <= 0.5)
    assert set(policy.last_timing_ms) == {"preprocess", "inference"}
    feeds = policy.preprocess(render(0.0), render(0.1))
    assert feeds["current"].shape == (1, 3, H, W) and feeds["current"].dtype == np.float32
    np.testing.assert_allclose(policy.postprocess(policy.infer(feeds)), ahead)


def test_nonfinite_output_becomes_zero_command_and_is_counted(tmp_path):
    policy = OnnxPolicy(build_velocitynet_onnx(str(tmp_path / "nan.onnx"), output_scale=float("nan")))
    out = policy.predict(render(0.0), render(0.1))
    assert np.array_equal(out, np.zeros((2, 2), dtype=np.float32))
    assert policy.nonfinite_count == 1


def test_out_of_range_outputs_are_clipped_to_model_limits(tmp_path):
    policy = OnnxPolicy(build_velocitynet_onnx(str(tmp_path / "big.onnx"), output_scale=10.0))
    out = policy.predict(render(0.0), render(0.5))
    assert out[0, 0] == pytest.approx(0.5)


def test_wrong_image_shape_is_refused(model_path):
    policy = OnnxPolicy(model_path)
    with pytest.raises(ValueError, match=r"image \(8, 8, 3\) uint8, expected \(16, 16, 3\)"):
        policy.predict(render(0.0, 8, 8), render(0.0, 8, 8))


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"input_names": ("image", "goal")}, "inputs are"),
        ({"output_name": "twist"}, "outputs are"),
        ({"drop_meta": ("vtr.horizon",)}, "lacks 'vtr.horizon'"),
        ({"meta_overrides": {"vtr.preprocessing": "bgr_minus_mean"}}, "preprocessing"),
        ({"meta_overrides": {"vtr.image_height": "32"}}, "expected (B, 3, 32"),
        ({"meta_overrides": {"vtr.horizon": "3"}}, "expected (B, 2, 3)"),
        ({"meta_overrides": {"vtr.format_version": "9"}}, "format version 9"),
    ],
)
def test_mismatched_models_are_refused(tmp_path, kwargs, fragment):
    path = build_velocitynet_onnx(str(tmp_path / "bad.onnx"), **kwargs)
    with pytest.raises(ModelMismatchError) as info:
        OnnxPolicy(path)
    assert fragment in str(info.value)


def test_not_an_onnx_file_and_missing_file(tmp_path):
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(ModelMismatchError, match="cannot load"):
        OnnxPolicy(junk)
    with pytest.raises(FileNotFoundError):
        OnnxPolicy(tmp_path / "missing.onnx")
    with pytest.raises(ValueError, match="threads"):
        OnnxPolicy(junk, threads=0)


def test_route_at_another_resolution_is_refused(model_path):
    policy = OnnxPolicy(model_path)
    policy.check_route(corridor_route())
    with pytest.raises(ModelMismatchError, match="route images are 8x8"):
        policy.check_route(corridor_route(h=8, w=8))


def test_a_model_file_past_the_size_cap_is_refused_before_onnxruntime_reads_it(tmp_path):
    big = tmp_path / "big.onnx"
    big.write_bytes(bytes(4096))
    with pytest.raises(ModelMismatchError, match="larger than"):
        OnnxPolicy(big, max_bytes=1024)


def test_postprocess_zeroes_exactly_the_outputs_with_a_non_finite_value(tmp_path):
    policy = OnnxPolicy(build_velocitynet_onnx(str(tmp_path / "m.onnx")))
    big = np.float32(3e38)  # finite, but a float32 sum of two would overflow
    for bad in (np.nan, np.inf, -np.inf):
        raw = np.zeros((2, policy.meta.horizon), dtype=np.float32)
        raw[1, -1] = bad
        assert not policy.postprocess(raw).any()
    raw = np.full((2, policy.meta.horizon), big, dtype=np.float32)
    raw[0, 0] = -big
    out = policy.postprocess(raw)
    assert out[0, 0] == -policy.meta.v_max and out[1, 0] == policy.meta.w_max
    assert policy.nonfinite_count == 3


def test_the_current_tensor_is_to_nchws_and_the_tensors_are_c_ordered(model_path):
    policy = OnnxPolicy(model_path)
    current, subgoal = render(0.0), render(0.1)
    feeds = policy.preprocess(current, subgoal)
    for name, image in (("current", current), ("subgoal", subgoal)):
        assert np.array_equal(feeds[name], to_nchw(image)) and feeds[name].flags.c_contiguous
    # a frame given by its planar levels (light matching's output) steers as the same image does
    planar = policy.predict(Frame.from_levels(current.transpose(2, 0, 1).astype(np.float32)), subgoal)
    assert np.array_equal(planar, policy.predict(current, subgoal))


def test_a_subgoals_tensor_is_made_once_and_kept_on_its_frame(model_path):
    policy = OnnxPolicy(model_path)
    current, subgoal = as_frame(render(0.0)), as_frame(render(0.1))
    first = policy.preprocess(current, subgoal)["subgoal"]
    assert policy.preprocess(render(0.2), subgoal)["subgoal"] is first and not first.flags.writeable
    assert np.array_equal(first, to_nchw(subgoal.image))
