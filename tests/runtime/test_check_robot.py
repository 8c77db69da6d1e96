"""`vtr check-robot`: our simulator passes every check; each fault of a broken bridge fails the check meant for it."""

from __future__ import annotations

import time

import pytest
from faulty_robot import FaultyRobot

from vtr.runtime import cli
from vtr.runtime.check_robot import CHECKS, FAIL, PASS, SKIP, WARN, run_checks
from vtr.sim2d import SimConfig, Simulator
from vtr.sim2d.server import ServerConfig, ServerThread


@pytest.fixture(scope="module")
def simulator() -> Simulator:
    sim = Simulator(SimConfig())
    sim.reset()
    return sim


@pytest.mark.parametrize("mode", ["lockstep", "realtime"])
def test_our_simulator_passes_every_check(simulator: Simulator, mode: str) -> None:
    with ServerThread(simulator, ServerConfig(bind="tcp://127.0.0.1:*", mode=mode)) as server:
        results = run_checks(server.endpoint, timeout_s=2.0)
    assert [r.name for r in results] == [name for name, _, _ in CHECKS]
    # Round-trip latency depends on the machine's load: a WARN there is not a conformance failure
    # (speed belongs in benchmarks, not tests).
    bad = [(r.name, r.status, r.detail) for r in results if r.status != PASS]
    assert all(name == "latency" and status == WARN for name, status, _ in bad), bad


def test_a_camera_only_robot_passes_the_scan_check_saying_so(simulator: Simulator) -> None:
    with ServerThread(simulator, ServerConfig(bind="tcp://127.0.0.1:*", scan=False)) as server:
        found = {r.name: r for r in run_checks(server.endpoint, timeout_s=2.0)}
    assert (found["scan"].status, found["scan"].detail) == (PASS, "no range sensor: camera-only safety")


def test_our_simulators_executed_twist_is_checked(simulator: Simulator) -> None:
    with ServerThread(simulator) as server:
        found = {r.name: r for r in run_checks(server.endpoint, timeout_s=2.0)}
    assert found["twist"].status == PASS and found["twist"].detail.startswith("commanded; turning at w=0.5")
    with ServerThread(simulator, ServerConfig(bind="tcp://127.0.0.1:*", twist=False)) as server:
        found = {r.name: r for r in run_checks(server.endpoint, timeout_s=2.0)}
    assert (found["twist"].status, found["twist"].detail) == (
        PASS,
        "not reported: `vtr teach --follow` goes by the pose",
    )


def test_our_simulators_scan_is_reported(simulator: Simulator) -> None:
    with ServerThread(simulator) as server:
        found = {r.name: r for r in run_checks(server.endpoint, timeout_s=2.0)}
    assert found["scan"].status == PASS
    assert found["scan"].detail.startswith("181 beams over 270 deg, range_max 5 m, mounted 0.1 m ahead")


def test_the_cli_prints_one_line_per_check_and_exits_zero(
    simulator: Simulator, capsys: pytest.CaptureFixture[str]
) -> None:
    with ServerThread(simulator) as server:
        assert cli.main(["check-robot", server.endpoint]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == len(CHECKS) + 2
    assert out[-1].startswith("summary: conformant:") and f"{len(CHECKS)} passed" in out[-1]


@pytest.mark.parametrize(
    ("fault", "check", "expected", "words"),
    [
        ("no_limits", "hello.fields", FAIL, "hello field 'limits' must be an object"),
        ("no_camera", "hello.fields", FAIL, "camera must be an object"),
        ("hello_two_wrong", "hello.fields", FAIL, "got None; hello field 'mode' must be one of"),
        ("old_hello", "hello.fields", WARN, "does not announce 'dt' and 'mode'"),
        ("wrong_size", "reset", FAIL, "64x64 but hello announced 128x128"),
        ("bare_errors", "errors", FAIL, "wrong protocol None"),
        ("bare_stop", "stop", FAIL, "carries proto, version, cmd, seq"),
        ("accepts_over_limit", "limits.enforced", FAIL, "was accepted"),
        ("zero_step_moves", "step.zero", FAIL, "a zero step changed the image"),
        ("frozen_camera", "step.turn", FAIL, "changed the image by only"),
        ("clockwise", "step.turn", FAIL, "REP-103"),
        ("stamp_back", "stamps", FAIL, "stamps never go back"),
        ("silent_on_bad", "errors", FAIL, "no reply"),
        ("slow", "latency", WARN, "control step"),
        ("ignores_session", "session.guard", FAIL, "session_mismatch"),
        ("no_watchdog", "watchdog", FAIL, "still turning"),
        ("scan_short", "scan", FAIL, "has 180 values, but hello announced 181 beams"),
        ("scan_missing", "scan", FAIL, "the 'observe' reply carries no 'scan'"),
        ("scan_unannounced", "scan", WARN, "hello does not announce one"),
        ("twist_missing", "twist", FAIL, "the 'observe' reply carries no 'twist'"),
        ("twist_backwards", "twist", FAIL, "counter-clockwise positive"),
        ("twist_unannounced", "twist", WARN, "hello does not announce one"),
    ],
)
def test_each_fault_fails_its_check(
    simulator: Simulator, fault: str, check: str, expected: str, words: str
) -> None:
    with FaultyRobot(simulator, fault) as robot:
        results = run_checks(robot.endpoint, timeout_s=0.5)
    found = {r.name: r for r in results}
    assert found[check].status == expected, found[check]
    assert words in found[check].detail
    if check != "hello":
        assert found["hello"].status == PASS  # one fault does not hide the rest of the report
    assert any(r.status == FAIL for r in results) == (expected == FAIL)


def test_a_silent_endpoint_fails_fast_and_skips_the_rest() -> None:
    t0 = time.monotonic()
    results = run_checks("tcp://127.0.0.1:9", timeout_s=0.3)  # nothing listens there
    assert time.monotonic() - t0 < 3
    assert results[0].status == FAIL and "no reply" in results[0].detail
    assert {r.status for r in results[1:]} == {SKIP}


def test_cli_exit_code_is_one_on_failure(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["check-robot", "tcp://127.0.0.1:9", "--timeout", "0.2"]) == 1
    assert "NOT conformant" in capsys.readouterr().out


def test_cli_refuses_an_address_that_is_not_an_endpoint(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:  # argparse's usage error: one line, exit 2
        cli.main(["check-robot", "localhost:5555"])
    assert exit_.value.code == 2 and "has no transport" in capsys.readouterr().err
    assert cli.main(["check-robot"]) == 2  # no address from the command line or a config file
    assert "needs ADDR" in capsys.readouterr().err


def test_wrong_hello_fields_are_each_reported_and_every_other_check_still_runs(simulator: Simulator) -> None:
    with FaultyRobot(simulator, "hello_two_wrong") as robot:
        found = {r.name: r for r in run_checks(robot.endpoint, timeout_s=0.5)}
    assert found["hello"].status == PASS and found["hello.fields"].status == FAIL
    ran = [name for name, r in found.items() if r.status in (PASS, WARN)]
    assert {"reset", "observe", "step.turn", "limits.enforced", "errors", "stop"} <= set(ran), found


def test_a_bridge_written_for_the_first_protocol_text_passes_with_warnings(simulator: Simulator) -> None:
    with FaultyRobot(simulator, "old_hello") as robot:
        results = run_checks(robot.endpoint, timeout_s=0.5)
    assert not [r for r in results if r.status == FAIL], results
    fields = {r.name: r for r in results}["hello.fields"].detail
    assert (
        "add them" in fields and "'camera.camera_height', a deprecated name: say 'camera.height_m'" in fields
    )


@pytest.mark.parametrize(
    ("size", "fov", "status", "says"),
    [
        (
            (160, 120),
            106.26,
            PASS,
            "for a model of the 90 deg / 0.30 m camera: camera 160x120 of 106.3 deg: the centre 120x120 -> ",
        ),
        (
            (640, 480),
            140.0,
            PASS,
            "cropped further (camera 640x480 of 140 deg: the centre 232.9x232.9 -> 128x128, fov 90 deg",
        ),
        (
            (160, 120),
            90.0,
            WARN,
            "a model of the 90 deg / 0.30 m camera cannot take this camera: the robot's field of view is 73.74",
        ),
    ],
)
def test_the_image_check_reports_how_the_camera_maps_to_the_trained_camera(size, fov, status, says) -> None:
    from vtr.sim2d.config import camera_config

    sim = Simulator(SimConfig(camera=camera_config(*size, (fov, 0.3))))
    sim.reset()
    with ServerThread(sim, ServerConfig(bind="tcp://127.0.0.1:*", scan=False)) as server:
        found = {r.name: r for r in run_checks(server.endpoint, timeout_s=2.0)}
    image = found["image"]
    assert image.status == status and says in image.detail, image.detail


def test_the_image_check_compares_with_the_model_the_robot_will_run() -> None:
    """An 87 deg camera at 0.45 m is refused by a model of the trained camera alone (2 deg / 2 cm) and taken by
    a model whose metadata gives a range it lies in (runtime.model_meta.CameraRange, as the shipped one's does):
    `vtr check-robot --model` says what `vtr repeat --model` will do."""
    from vtr.runtime.model_meta import CameraRange, ModelMeta
    from vtr.sim2d.config import camera_config

    ranged = ModelMeta(**CameraRange((85.0, 110.0), (0.2, 0.55)).props())
    sim = Simulator(SimConfig(camera=camera_config(128, 128, (87.0, 0.45))))
    sim.reset()
    with ServerThread(sim, ServerConfig(bind="tcp://127.0.0.1:*", scan=False)) as server:
        shipped = {r.name: r for r in run_checks(server.endpoint, timeout_s=2.0)}["image"]
        model = {r.name: r for r in run_checks(server.endpoint, timeout_s=2.0, model=ranged)}["image"]
    assert shipped.status == WARN and "90 deg / 0.30 m camera cannot take this camera" in shipped.detail
    assert shipped.detail.endswith("pass --model to check with the model the robot will run")
    assert model.status == PASS and "the model's input as it is" in model.detail, model.detail
