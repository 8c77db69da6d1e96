"""`vtr teach --drive`: a route taught by keyboard in a (pseudo-)terminal is repeated to the end; Esc and Ctrl-C
save nothing and leave the robot stopped and the terminal as it was."""

from __future__ import annotations

import signal
import termios
from pathlib import Path

import pytest
from terminal import ROOT, Terminal

from vtr.runtime.daemon import RepeatRunConfig
from vtr.runtime.daemon import run as repeat
from vtr.runtime.route import Route
from vtr.runtime.teleop_keys import Teleop, decode_keys
from vtr.sim2d import Pose, SimConfig, Simulator
from vtr.sim2d.server import ServerConfig, ServerThread

UP, LEFT, RIGHT = b"\x1b[A", b"\x1b[D", b"\x1b[C"
START = Pose(7.2, 1.2, 0.0)  # the kitchen, facing a clear stretch (sim2d/routes/kitchen_arc.json)


@pytest.fixture(scope="module")
def simulator() -> Simulator:
    return Simulator(SimConfig())


def _teach(endpoint: str, out: Path, *extra: str) -> Terminal:
    term = Terminal("teach", "--drive", "--sim", endpoint, "--out", str(out), *extra)
    term.wait_for(b"q or Enter saves")
    return term


def test_a_route_taught_by_keyboard_in_a_terminal_is_repeated_to_the_end(simulator, tmp_path):
    simulator.reset(pose=START)
    out = tmp_path / "route.npz"
    with ServerThread(simulator, ServerConfig(bind="tcp://127.0.0.1:*")) as server:
        term = _teach(server.endpoint, out)
        term.press(UP * 3 + b"w" * 2, then=1.5)  # 0.25 m/s ahead
        term.press(LEFT * 3, then=1.5)  # and a left arc
        term.press(RIGHT * 3, then=1.0)  # straight again
        term.press(b"q")
        assert term.finish() == 0, term.text()
        assert "subgoals (steps spacing)" in term.text() and "robot: ok" in term.text()
        assert "v +0.25 m/s  w +0.30 rad/s" in term.text()  # the live line showed the held command
        route = Route.load(out)
        assert len(route) >= 10 and route.spacing["rule"] == "steps"
        assert abs(route.poses[0][0] - START.x) < 1e-6 and route.poses[-1][0] > START.x + 0.5
        assert route.poses[-1][2] > 0.2  # it turned left
        assert route.commands.max(axis=0).tolist() == pytest.approx([0.25, 0.3])
        summary = repeat(
            RepeatRunConfig(sim=server.endpoint, model=str(ROOT / "models/velocitynet.onnx"), route=str(out))
        )
    assert summary.status == "finished" and summary.subgoals_reached == len(route), summary


@pytest.mark.parametrize("key", [b"\x1b", b"\x03", None], ids=["esc", "ctrl-c", "sigterm"])
def test_esc_ctrl_c_and_sigterm_save_nothing_and_stop_the_robot(simulator, tmp_path, key):
    simulator.reset(pose=START)
    out = tmp_path / "route.npz"
    cfg = ServerConfig(bind="tcp://127.0.0.1:*", mode="realtime", cmd_vel_timeout=5.0)
    with ServerThread(simulator, cfg) as server:
        term = _teach(server.endpoint, out)
        term.press(UP * 4, then=0.6)
        assert server.server.twist[0] == pytest.approx(0.2)  # driving, the watchdog fed every period
        if key is None:
            term.proc.send_signal(signal.SIGTERM)
        else:
            term.press(key)
        code = term.finish()
        assert server.server.twist == (0.0, 0.0) and server.server.last_cmd == "stop"
        assert server.server.watchdog_stops == 0  # the teach stopped it, not the robot's timeout
    assert code == 130 and "; nothing saved" in term.text(), term.text()
    assert not out.exists()


def test_the_terminal_is_restored_on_every_way_out(simulator, tmp_path):
    simulator.reset(pose=START)
    with ServerThread(simulator, ServerConfig(bind="tcp://127.0.0.1:*")) as server:
        for key in (b"q", b"\x1b"):
            term = Terminal("teach", "--drive", "--sim", server.endpoint, "--out", str(tmp_path / "r.npz"))
            cooked = term.cooked
            term.wait_for(b"q or Enter saves")
            assert termios.tcgetattr(term.fd) != cooked  # raw while driving
            term.press(key)
            term.proc.wait(30)
            assert termios.tcgetattr(term.fd) == cooked, key
            term.finish()


def test_drive_needs_a_terminal(capsys):
    from vtr.cli import main

    assert main(["teach", "--drive", "--sim", "tcp://127.0.0.1:1", "--out", "x.npz"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "stdin is not one" in err


def test_keys_decode_arrows_split_across_reads_and_a_lone_esc():
    assert decode_keys(b"w\x1b[Aa \r") == (["w", "up", "a", "space", "enter"], b"")
    assert decode_keys(b"\x1b[") == ([], b"\x1b[")  # the rest of the arrow is still on its way
    assert decode_keys(b"\x1b[")[1] + b"D" == b"\x1b[D" and decode_keys(b"\x1b[D")[0] == ["left"]
    assert decode_keys(b"\x1bq") == (["esc", "q"], b"")
    assert decode_keys(b"\x03") == (["ctrl-c"], b"")


def test_the_teleop_steps_within_the_robots_limits():
    t = Teleop(v_max=0.12, w_max=0.25)
    for _ in range(5):
        t.press("up")
        t.press("left")
    assert (t.v, t.w) == (0.12, 0.25)
    t.press("space")
    assert (t.v, t.w) == (0.0, 0.0)
    t.press("down")
    t.press("d")
    assert (t.v, t.w) == (-0.05, -0.1)
    assert t.press("q") == "finish" and t.press("enter") == "finish"
    assert t.press("esc") == "abort" and t.press("ctrl-c") == "abort" and t.press("x") is None


def test_one_recorder_spaces_every_teach_and_standing_still_adds_nothing():
    import numpy as np

    from vtr.runtime.robot import Observation
    from vtr.runtime.teach import TeachConfig
    from vtr.runtime.teach_record import TeachRecorder

    def at(x: float) -> Observation:
        return Observation(image=np.full((2, 2, 3), int(x * 100), np.uint8), stamp=x, pose=(x, 0.0, 0.0))

    rec = TeachRecorder(TeachConfig(), at(0.0))
    for i in range(1, 4):
        rec.step(0.2, 0.0, at(i * 0.02))
    for _ in range(50):  # the driver stops to think: no subgoals of the same view
        rec.step(0.0, 0.0, at(0.06), moving=False)
    rec.step(0.0, 0.3, at(0.06))  # a turn in place moves
    route = rec.finish("r", {})
    assert route.poses[:, 0].tolist() == [0.0, 0.04, 0.06] and len(route) == 3
    assert route.commands.tolist() == [[0.2, 0.0], [0.2, 0.0], [0.0, 0.0]]
