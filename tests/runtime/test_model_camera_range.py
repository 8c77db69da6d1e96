"""A model trained across cameras takes any robot camera inside its range; a model of one camera keeps the
2 deg / 2 cm rule; the export writes the range the training data spans."""

from __future__ import annotations

import pytest

from vtr.export.provenance import camera_of
from vtr.runtime.contracts import CameraSpec
from vtr.runtime.hello import CameraMismatchError, Hello, check_camera_range, fit_robot
from vtr.runtime.model_meta import CameraRange, ModelMeta
from vtr.runtime.protocol import Limits

RANGE = CameraRange((60.0, 120.0), (0.15, 0.6))


def _hello(fov: float | None, height: float | None, size: int = 128) -> Hello:
    return Hello(
        session="s",
        stamp=0.0,
        protocol_version=1,
        camera=CameraSpec(size, size, fov, height),
        limits=Limits(v_max=0.5, w_max=1.0, max_duration=10.0),
        dt=0.1,
        mode="lockstep",
    )


def test_the_range_travels_in_the_metadata():
    meta = ModelMeta(**RANGE.props())
    back = ModelMeta.from_props(meta.to_props())
    assert back.camera_range == RANGE and str(RANGE) == "fov 60-120 deg, height 0.15-0.6 m"
    old = {k: v for k, v in ModelMeta().to_props().items()}  # a model of one camera: no range
    assert ModelMeta.from_props(old).camera_range is None


@pytest.mark.parametrize(("fov", "height"), [(60.0, 0.15), (70.0, 0.45), (110.0, 0.2), (121.5, 0.61)])
def test_a_robot_inside_the_range_is_accepted(fov, height):
    meta = ModelMeta(**RANGE.props())
    route = {"width": 128, "height": 128, "fov_deg": fov, "height_m": height}
    assert fit_robot(_hello(fov, height), route, meta)[1] == []


@pytest.mark.parametrize(
    ("fov", "height", "what"), [(50.0, 0.3, "field of view"), (90.0, 0.7, "camera height")]
)
def test_a_robot_outside_the_range_is_refused_in_one_line_with_the_fine_tune(fov, height, what):
    meta = ModelMeta(**RANGE.props())
    with pytest.raises(CameraMismatchError) as err:
        fit_robot(_hello(fov, height), None, meta)[1]
    msg = str(err.value)
    assert "\n" not in msg and what in msg and "fov 60-120 deg, height 0.15-0.6 m" in msg
    assert "vtr train velocitynet --init models/velocitynet.pt" in msg


def test_the_route_must_still_match_the_robot_exactly():
    meta = ModelMeta(**RANGE.props())
    route = {"width": 128, "height": 128, "fov_deg": 70.0, "height_m": 0.3}
    with pytest.raises(CameraMismatchError, match="but the route was made with 70 deg"):
        fit_robot(_hello(100.0, 0.3), route, meta)[1]


def test_a_model_of_one_camera_keeps_the_two_degree_rule():
    meta = ModelMeta()  # 90 deg, 0.3 m, no range
    assert meta.camera_range is None
    fit_robot(_hello(91.5, 0.31), None, meta)[1]
    with pytest.raises(CameraMismatchError, match="tolerance 2 deg") as err:
        fit_robot(_hello(87.0, 0.3), None, meta)[1]
    assert "vtr train velocitynet" in str(err.value)  # the fine-tune command
    mapping, _ = fit_robot(_hello(93.0, 0.3), None, meta)  # wider: cropped to what the model saw
    assert mapping.narrowed and mapping.seen_fov_deg == pytest.approx(90.0)


def test_unknown_robot_camera_and_wrong_size():
    meta = ModelMeta(**RANGE.props())
    notes = check_camera_range(CameraSpec(128, 128, None, 0.3), meta)
    assert notes and "unknown" in notes[0]
    with pytest.raises(CameraMismatchError, match="gives 64x64 images"):
        check_camera_range(CameraSpec(64, 64, 90.0, 0.3), meta)


def test_half_a_range_is_an_error():
    with pytest.raises(ValueError, match="needs all four"):
        ModelMeta(camera_fov_min_deg=60.0)
    with pytest.raises(ValueError, match="bad camera range"):
        ModelMeta(**CameraRange((120.0, 60.0), (0.15, 0.6)).props())


def test_export_writes_the_range_the_data_spans():
    one = camera_of(
        {"camera": {"fov_deg": 90.0, "camera_height": 0.3}, "cameras": [[90.0, 0.3], [90.0, 0.3]]}
    )
    assert one == {"camera_fov_deg": 90.0, "camera_height_m": 0.3}  # one camera: no range
    many = camera_of({"camera": {"fov_deg": 90.0}, "cameras": [[65.0, 0.2], [105.0, 0.5], [90.0, 0.3]]})
    assert ModelMeta(**many).camera_range == CameraRange((65.0, 105.0), (0.2, 0.5))
    with pytest.raises(ValueError, match="pairs"):
        camera_of({"cameras": [["x"]]})


def test_a_range_is_read_from_text_or_refused_in_one_line():
    assert CameraRange.parse("65-105,0.2-0.45") == CameraRange((65.0, 105.0), (0.2, 0.45))
    for bad in (
        "65-105",
        "65,0.2",
        "a-b,0.2-0.4",
        "105-65,0.2-0.4",
        "65-200,0.2-0.4",
        "65-105,0.2-nan",
        "65-105,0-0.4",
    ):
        with pytest.raises(ValueError) as err:
            CameraRange.parse(bad)
        assert repr(bad) in str(err.value) and "\n" not in str(err.value)
