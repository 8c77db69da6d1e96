"""`vtr teach --follow`: a route recorded while the robot is driven by its own joystick (the simulator's drive
script plays the joystick) sends no motion command, is spaced like any teach, and is repeated to the end."""

from __future__ import annotations

import time

import numpy as np
import pytest
from terminal import ROOT, Terminal

from vtr.runtime.daemon import RepeatRunConfig
from vtr.runtime.daemon import run as repeat
from vtr.runtime.robot import Observation
from vtr.runtime.route import Route
from vtr.runtime.route_script import parse_route_script
from vtr.runtime.teach_drive import executed
from vtr.sim2d import SimConfig, Simulator
from vtr.sim2d.server import ServerConfig, ServerThread

JOYSTICK = parse_route_script(
    {
        "name": "joystick",
        "start": {"x": 7.2, "y": 1.2, "yaw": 0.0},
        "segments": [
            {"v": 0.25, "w": 0.0, "duration": 1.0},
            {"v": 0.25, "w": 0.3, "duration": 1.0},
            {"v": 0.25, "w": 0.0, "duration": 0.8},
        ],
    }
)


@pytest.fixture(scope="module")
def simulator() -> Simulator:
    return Simulator(SimConfig())


@pytest.mark.parametrize("twist", [True, False], ids=["executed-twist", "pose-only"])
def test_a_route_recorded_while_someone_else_drives_is_repeated_to_the_end(simulator, tmp_path, twist):
    out = tmp_path / "route.npz"
    cfg = ServerConfig(bind="tcp://127.0.0.1:*", mode="realtime", drive_script=JOYSTICK, twist=twist)
    with ServerThread(simulator, cfg) as server:
        term = Terminal("teach", "--follow", "--sim", server.endpoint, "--out", str(out))
        term.wait_for(b"q or Enter saves")
        driver = server.server.driver
        deadline = time.monotonic() + 30
        while driver.holding(float(simulator.time)) and time.monotonic() < deadline:
            term.read(0.1)  # the robot drives its script; the follower only watches
        term.read(0.5)
        term.press(b"\r")
        assert term.finish() == 0, term.text()
        assert set(server.server.served) == {"hello", "observe"}  # not one motion command, not even a stop
        route = Route.load(out)
        assert 4 <= len(route) <= 20 and route.spacing["rule"] == "steps"  # 28 periods of 0.1 s, every 2nd
        assert route.poses[0] == pytest.approx([7.2, 1.2, 0.0], abs=0.03)
        assert route.poses[-1] == pytest.approx(simulator.pose, abs=0.03)  # it stood still at the end
        assert route.commands[:, 0].max() == pytest.approx(0.25, abs=0.02)
        assert route.commands[:, 1].max() == pytest.approx(0.3, abs=0.03)
        if twist:
            summary = repeat(
                RepeatRunConfig(
                    sim=server.endpoint, model=str(ROOT / "models/velocitynet.onnx"), route=str(out)
                )
            )
            assert summary.status == "finished" and summary.subgoals_reached == len(route), summary


def test_the_executed_motion_comes_from_the_twist_else_from_the_pose():
    image = np.zeros((2, 2, 3), np.uint8)
    at = lambda pose, twist=None, stamp=0.0: Observation(image=image, stamp=stamp, pose=pose, twist=twist)  # noqa: E731
    assert executed(at((0, 0, 0)), at((5, 5, 1), (0.2, -0.1)), 0.1) == (0.2, -0.1, True)
    late = executed(at((0, 0, 0), stamp=1.0), at((0.04, 0, 0), stamp=1.2), 0.1)  # a reply 0.1 s late
    assert late[0] == pytest.approx(0.2)
    assert executed(at((0, 0, 0)), at((0, 0, 0), (0.0, 0.0)), 0.1)[2] is False
    v, w, moving = executed(at((1.0, 1.0, 1.5707963)), at((1.0, 1.02, 1.6707963)), 0.1)
    assert (v, w, moving) == (pytest.approx(0.2), pytest.approx(1.0), True)
    assert executed(at((1.0, 1.0, 0.0)), at((1.0, 1.0, 0.0)), 0.1)[2] is False
    with pytest.raises(Exception, match="neither its executed twist nor its pose"):
        executed(at(None), at(None), 0.1)


def test_a_drive_script_needs_realtime():
    with pytest.raises(ValueError, match="needs --mode realtime"):
        ServerConfig(drive_script=JOYSTICK)


def test_while_its_joystick_drives_the_robot_refuses_motion_commands_then_takes_them(simulator):
    from vtr.runtime.client import SimClient
    from vtr.runtime.robot import RobotError

    script = parse_route_script(
        {"start": {"x": 7.2, "y": 1.2, "yaw": 0.0}, "segments": [{"v": 0.2, "w": 0.0, "duration": 0.5}]}
    )
    cfg = ServerConfig(bind="tcp://127.0.0.1:*", mode="realtime", drive_script=script)
    with ServerThread(simulator, cfg) as server, SimClient(server.endpoint) as client:
        client.handshake()
        with pytest.raises(RobotError, match="driven by its own joystick"):
            client.step(0.1, 0.0, 0.1)  # before the script starts, too: the operator has the controls
        assert client.observe().twist == (0.2, 0.0)  # the first look starts the script
        time.sleep(0.7)
        moved = client.observe()
        assert moved.twist == (0.0, 0.0) and moved.pose[0] == pytest.approx(7.3, abs=0.02)
        assert client.step(0.0, 0.5, 0.1).twist == (0.0, 0.5)  # an ordinary robot once the script is over
