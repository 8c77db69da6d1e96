"""What a robot announces in hello, and the one-line refusals when robot, route and model do not fit."""

from __future__ import annotations

import json

import pytest

from vtr.runtime import protocol
from vtr.runtime.contracts import CameraSpec
from vtr.runtime.hello import (
    CameraMismatchError,
    RobotMismatchError,
    check_camera,
    fit_robot,
    parse_hello,
)
from vtr.runtime.model_meta import ModelMeta
from vtr.runtime.protocol import BadFrameError

HELLO = {
    "protocol_version": 1,
    "camera": {"width": 128, "height": 128, "fov_deg": 90.0, "height_m": 0.3},
    "limits": {"v_max": 0.5, "w_max": 1.0, "max_duration": 10.0},
    "dt": 0.02,
    "mode": "lockstep",
}


def hello(**changes) -> protocol.Reply:
    fields = {**HELLO, **changes}
    return protocol.decode_reply(protocol.encode_ok("hello", 1, "s", 0.0, **fields))


def test_a_complete_hello_parses():
    h = parse_hello(hello(map="house", cmd_vel_timeout=0.5, realtime_factor=2.0))
    assert h.camera == CameraSpec(128, 128, 90.0, 0.3) and h.limits.w_max == 1.0
    assert (h.map, h.cmd_vel_timeout, h.realtime_factor, h.mode) == ("house", 0.5, 2.0, "lockstep")


@pytest.mark.parametrize(
    "changes, fragment",
    [
        ({"camera": None}, "camera must be an object"),
        ({"camera": {"width": 128.0, "height": 128}}, "'width' must be an integer"),
        ({"camera": {"width": 0, "height": 128}}, "1..4096"),
        ({"limits": {"v_max": 0.5, "w_max": 1.0}}, "max_duration"),
        ({"dt": 0}, "'dt' must be > 0"),
        ({"mode": "turbo"}, "'mode' must be one of"),
        ({"protocol_version": "1"}, "protocol_version"),
        ({"mode": "realtime"}, "must announce 'cmd_vel_timeout'"),
    ],
)
def test_a_hello_missing_or_mistyping_a_field_is_refused_naming_it(changes, fragment):
    with pytest.raises(BadFrameError, match=fragment):
        parse_hello(hello(**changes))


ROBOT = CameraSpec(128, 128, 90.0, 0.3)


@pytest.mark.parametrize(
    "other, fragment",
    [
        (CameraSpec(160, 120, 90.0, 0.3), "128x128 images but the route was made with 160x120"),
        (CameraSpec(128, 128, 60.0, 0.3), "field of view is 90 deg but the route was made with 60 deg"),
        (CameraSpec(128, 128, 90.0, 0.5), "camera height is 0.3 m but the route was made with 0.5 m"),
    ],
)
def test_camera_mismatches_are_refused_in_one_line(other, fragment):
    with pytest.raises(CameraMismatchError, match=fragment) as info:
        check_camera(ROBOT, route=other, model=ROBOT)
    assert "\n" not in str(info.value)


def test_small_differences_pass_and_unknowns_are_noted_not_refused():
    assert check_camera(ROBOT, CameraSpec(128, 128, 91.5, 0.31), ROBOT) == []
    notes = check_camera(CameraSpec(128, 128, None, None), None, ROBOT)
    assert any("route records no camera" in n for n in notes) and any("field of view" in n for n in notes)


def test_the_robot_must_accept_what_the_model_commands():
    h = parse_hello(hello(limits={"v_max": 0.3, "w_max": 1.0, "max_duration": 10.0}))
    with pytest.raises(RobotMismatchError, match="v_max=0.5 m/s but the robot accepts at most 0.3") as info:
        fit_robot(h, {"width": 128, "height": 128}, ModelMeta())[1]
    slow = parse_hello(hello(dt=0.2))
    assert not isinstance(info.value, CameraMismatchError)  # the limits are not the camera
    with pytest.raises(RobotMismatchError, match="control step is 0.1 s"):
        fit_robot(slow, None, ModelMeta())[1]
    assert fit_robot(parse_hello(hello()), {"width": 128, "height": 128, "camera_height": 0.3}, ModelMeta())[
        1
    ]


def test_the_model_records_its_camera_and_older_models_without_it_still_load():
    props = ModelMeta(camera_fov_deg=70.0).to_props()
    assert ModelMeta.from_props(props).camera == CameraSpec(128, 128, 70.0, 0.3)
    older = {k: v for k, v in props.items() if "camera" not in k}
    assert ModelMeta.from_props(older).camera == CameraSpec(128, 128, None, None)
    assert json.dumps(ModelMeta().to_props())  # every value a string


def test_models_carrying_the_dropped_e_m_default_still_load():
    props = ModelMeta().to_props()
    assert "vtr.e_m_default" not in props  # read by nothing, no longer written
    assert ModelMeta.from_props({**props, "vtr.e_m_default": "17.0"}) == ModelMeta()


def test_vtr_repeat_refuses_in_one_line_a_robot_whose_camera_differs_from_the_route(tmp_path, capsys):
    from runtime_fakes import FakeSim, build_velocitynet_onnx, corridor_route

    from vtr.runtime.cli import main
    from vtr.sim2d.server import ServerThread

    model = build_velocitynet_onnx(str(tmp_path / "tiny.onnx"))
    route = corridor_route()
    route.camera = {"width": 16, "height": 16, "fov_deg": 60.0}  # taught with a narrower lens
    route.save(tmp_path / "route.npz")
    sim = FakeSim()
    with ServerThread(sim) as server:
        code = main(
            ["repeat", "--sim", server.endpoint, "--model", model, "--route", str(tmp_path / "route.npz")]
        )
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.count("\n") == 0
    assert "field of view is 90 deg but the route was made with 60 deg" in err
    assert [c for c in sim.calls if c[0] in ("reset", "step")] == []  # refused before anything moved
