"""A robot whose camera is not the model's input: `hello`'s camera check maps it (runtime.hello.fit_robot)
and judges the field of view the model then sees; `vtr teach --model` and `vtr repeat` map its frames alike,
so a route taught at one resolution is repeated at another of the same camera."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from vtr.runtime.contracts import CameraSpec
from vtr.runtime.hello import CameraMismatchError, Hello, fit_robot, mapping_notes
from vtr.runtime.model_meta import CameraRange, ModelMeta
from vtr.runtime.protocol import Limits

ROOT = Path(__file__).resolve().parents[2]
FOUR_THREE = 2 * math.degrees(math.atan(4 / 3))  # 106.26 deg: a 4:3 camera whose square centre sees 90 deg


def _hello(w: int, h: int, fov: float | None, height: float | None = 0.3) -> Hello:
    limits = Limits(v_max=0.5, w_max=1.0, max_duration=10.0)
    return Hello("s", 0.0, 1, CameraSpec(w, h, fov, height), limits, 0.1, "lockstep")


@pytest.mark.parametrize(("w", "h"), [(160, 120), (320, 240), (640, 480), (200, 150)])
def test_a_camera_whose_crop_sees_what_the_model_saw_is_accepted(w, h):
    mapping, notes = fit_robot(_hello(w, h, FOUR_THREE), None, ModelMeta())
    assert mapping.size == (128, 128) and mapping.crop == (pytest.approx((w - h) / 2), 0.0, h, h)
    assert mapping.seen_fov_deg == pytest.approx(90.0) and not mapping.narrowed
    assert "120x120" in mapping_notes(fit_robot(_hello(160, 120, FOUR_THREE), None, ModelMeta())[0])[0]
    assert notes == ["the route records no camera; not compared"]


def test_a_camera_whose_crop_sees_too_little_is_refused_with_the_numbers_and_the_fine_tune():
    with pytest.raises(CameraMismatchError) as err:
        fit_robot(_hello(160, 120, 90.0), None, ModelMeta())
    msg = str(err.value)
    assert "\n" not in msg and "73.74 deg" in msg and "160x120 of 90 deg" in msg and "120x120" in msg
    assert "but the model was made with 90 deg" in msg and "vtr train velocitynet --init" in msg


def test_a_model_trained_across_cameras_takes_any_crop_inside_its_range():
    meta = ModelMeta(**CameraRange((60.0, 120.0), (0.15, 0.6)).props())
    mapping, _ = fit_robot(_hello(160, 120, 90.0), None, meta)  # 73.7 deg: inside
    assert mapping.seen_fov_deg == pytest.approx(73.74, abs=0.01) and not mapping.narrowed
    wide, _ = fit_robot(_hello(640, 480, 170.0), None, meta)  # 161 deg after the square crop: narrowed
    assert wide.narrowed and wide.seen_fov_deg == pytest.approx(120.0)
    assert "wider than the model sees (120 deg)" in mapping_notes(wide)[0]
    with pytest.raises(CameraMismatchError, match="outside the cameras the model takes"):
        fit_robot(_hello(160, 120, 60.0), None, meta)  # 47 deg after the crop
    with pytest.raises(CameraMismatchError, match="camera height is 0.7 m"):
        fit_robot(_hello(160, 120, 90.0, 0.7), None, meta)


def test_the_route_is_compared_with_what_the_model_sees():
    route = {"width": 128, "height": 128, "fov_deg": 90.0, "height_m": 0.3, "native": {"width": 160}}
    assert fit_robot(_hello(640, 480, FOUR_THREE), route, ModelMeta())[1] == []  # taught at 160x120
    with pytest.raises(CameraMismatchError, match="but the route was made with 90 deg"):
        fit_robot(_hello(640, 480, 115.0), {**route, "fov_deg": 90.0}, ModelMeta(camera_fov_deg=98.0))


def _teach_and_repeat(sim_size: tuple[int, int], route: Path, script: Path, capsys, teach: bool) -> dict:
    from vtr.cli import main
    from vtr.sim2d import SimConfig, Simulator
    from vtr.sim2d.config import camera_config
    from vtr.sim2d.server import ServerConfig, ServerThread

    w, h = sim_size
    sim = Simulator(SimConfig(camera=camera_config(w, h, (FOUR_THREE, 0.3))))
    model = str(ROOT / "models" / "velocitynet.onnx")
    with ServerThread(sim, ServerConfig(bind="tcp://127.0.0.1:*", scan=False)) as server:
        if teach:
            argv = ["teach", "--sim", server.endpoint, "--route", str(script), "--out", str(route)]
            assert main([*argv, "--model", model]) == 0
        capsys.readouterr()
        assert (
            main(["repeat", "--sim", server.endpoint, "--model", model, "--route", str(route), "--json"]) == 0
        )
    out = capsys.readouterr()
    assert f"camera {w}x{h} of 106.3 deg: the centre {h}x{h} -> 128x128, fov 90 deg" in out.err
    return json.loads(out.out)


def test_a_route_taught_at_160x120_is_repeated_there_and_at_200x150(tmp_path, capsys):
    from vtr.runtime.route import Route

    script = tmp_path / "short.json"
    segments = [{"v": 0.25, "w": 0.0, "duration": 2.0}, {"v": 0.2, "w": 0.4, "duration": 2.0}]
    script.write_text(json.dumps({"start": {"x": 2.0, "y": 3.0, "yaw": 0.0}, "segments": segments}))
    route = tmp_path / "route.npz"
    summary = _teach_and_repeat((160, 120), route, script, capsys, teach=True)
    taught = Route.load(route)
    assert taught.image_shape == (128, 128) and taught.camera["fov_deg"] == pytest.approx(90.0)
    assert taught.camera["native"]["width"] == 160 and taught.camera["crop"] == [20.0, 0.0, 120.0, 120.0]
    assert summary["status"] == "finished" and summary["subgoals_reached"] == len(taught)
    again = _teach_and_repeat((200, 150), route, script, capsys, teach=False)  # a non-integer factor
    assert again["status"] == "finished" and again["subgoals_reached"] == len(taught)
    assert np.isfinite(again["e_m"])
