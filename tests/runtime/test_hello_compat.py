"""Protocol version 1 keeps its promises: a bridge written for the protocol's first text (a hello without `dt`
and `mode`, `camera_height` for `height_m`) is taught and driven by `vtr teach` and `vtr repeat` alike, each
warning what it should add; a robot speaking another protocol_version is refused naming the one needed."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from faulty_robot import FaultyRobot

from vtr.cli import main
from vtr.runtime import protocol
from vtr.runtime.hello import ADDED_FIELDS, accept_hello, parse_hello, read_hello
from vtr.sim2d import SimConfig, Simulator

ROOT = Path(__file__).resolve().parents[2]
MODEL = str(ROOT / "models" / "velocitynet.onnx")
SCRIPT = str(ROOT / "sim2d" / "routes" / "translation.json")
FIRST_TEXT = {  # what hello carried before the fields of ADDED_FIELDS were written down
    "protocol_version": 1,
    "camera": {"width": 128, "height": 128, "fov_deg": 90.0, "camera_height": 0.3},
    "limits": {"v_max": 0.5, "w_max": 1.0, "max_duration": 10.0},
    "time": 0.0,
    "info": {},
}


def _reply(**fields: object) -> protocol.Reply:
    return protocol.decode_reply(protocol.encode_ok("hello", 1, "s", 0.0, **fields))


def test_the_first_texts_hello_parses_and_takes_the_documented_defaults() -> None:
    hello = parse_hello(_reply(**FIRST_TEXT))
    assert (hello.dt, hello.mode, hello.cmd_vel_timeout, hello.scan) == (None, None, None, None)
    assert hello.camera.height_m == 0.3 and hello.deprecated == ("camera.camera_height",)
    accepted, warnings = accept_hello(hello, 0.1)
    assert accepted.dt == 0.1  # the route's
    assert "does not announce 'dt' and 'mode'" in warnings[0] and "the route's 0.1 s" in warnings[0]
    assert "say 'camera.height_m'" in warnings[1]
    assert set(ADDED_FIELDS) == {"dt", "mode", "cmd_vel_timeout", "realtime_factor", "scan", "twist"}
    assert hello.twist is None  # no executed twist: `vtr teach --follow` goes by the pose


def test_every_wrong_field_is_read_on_its_own() -> None:
    hello, problems = read_hello(
        _reply(**{**FIRST_TEXT, "limits": None, "mode": "turbo", "protocol_version": 2})
    )
    assert set(problems) == {"limits", "mode", "protocol_version"}
    assert "this runtime needs version 1" in problems["protocol_version"]
    assert hello.camera.width == 128 and hello.limits.v_max == 0.5  # read, and the paper's limits as fallback


@pytest.fixture(scope="module")
def old_bridge() -> Iterator[str]:
    sim = Simulator(SimConfig())
    with FaultyRobot(sim, "old_hello") as robot:
        yield robot.endpoint


def test_teach_and_repeat_drive_an_old_bridge_each_warning_what_to_add(
    old_bridge: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    route = str(tmp_path / "route.npz")
    assert main(["teach", "--sim", old_bridge, "--route", SCRIPT, "--out", route]) == 0
    taught = capsys.readouterr().err
    assert "vtr teach: warning: the robot's hello does not announce 'dt' and 'mode'" in taught
    code = main(["repeat", "--sim", old_bridge, "--model", MODEL, "--route", route, "--json"])
    repeated = capsys.readouterr().err
    assert code == 0, repeated
    assert "vtr repeat: warning: the robot's hello does not announce 'dt' and 'mode'" in repeated
    assert "camera.height_m" in taught and "camera.height_m" in repeated
