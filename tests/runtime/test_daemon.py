"""The repeat daemon: completes a route, keeps the robot still on bad frames, stops on every failure."""

from __future__ import annotations

import json
import threading
import time
from dataclasses import replace

import numpy as np
import pytest
from runtime_fakes import FakeSim, FakeSimAt, build_velocitynet_onnx, corridor_route, render, run_repeat

from vtr.runtime.client import SimClient
from vtr.runtime.controller import ControllerConfig
from vtr.runtime.policy import OnnxPolicy
from vtr.runtime.protocol import BadFrameError
from vtr.runtime.repeater import RepeatConfig
from vtr.runtime.robot import Observation
from vtr.sim2d.local_robot import LocalRobot
from vtr.sim2d.server import ServerConfig, ServerThread, start_server_process

LOG_KEYS = {
    "step",
    "subgoal",
    "from_subgoal",
    "advanced",
    "jumped_to",
    "error",
    "e_m",
    "v",
    "w",
    "stamp",
    "pose",
    "latency_ms",
}


@pytest.fixture(scope="module")
def policy_path(tmp_path_factory):
    return build_velocitynet_onnx(str(tmp_path_factory.mktemp("model") / "tiny.onnx"))


def test_repeat_in_process_completes_the_route_and_logs_every_step(policy_path):
    sim = FakeSim()
    records: list[dict] = []
    # the fake camera encodes position in brightness, which patch matching ignores by design: raw error
    cfg = RepeatConfig(controller=ControllerConfig.before())
    summary = run_repeat(LocalRobot(sim), OnnxPolicy(policy_path), corridor_route(), cfg, log=records.append)
    assert summary.completed and summary.subgoals_reached == 9 == summary.subgoals_total
    assert summary.e_m == pytest.approx(7.5)  # calibrated: 3/4 of the 10-level step between subgoals
    assert sim.pose.x == pytest.approx(0.4, abs=0.04)  # |error| <= e_m = 7.5 levels = 0.0375 m
    steps = [r for r in records if "step" in r]
    assert len(steps) == summary.steps > 0 and set(steps[0]) == LOG_KEYS
    assert {"preprocess", "inference", "error", "compute", "robot", "total"} <= set(steps[0]["latency_ms"])
    assert summary.sim_time_s == pytest.approx(0.1 * summary.steps)
    assert "robot" in summary.mean_latency_ms


class FlakyRobot:
    """Wraps a LocalRobot; chosen calls return a bad frame (raise BadFrameError or a wrong image)."""

    def __init__(self, inner: LocalRobot, bad_calls: set[int], mode: str) -> None:
        self.inner, self.bad_calls, self.mode = inner, bad_calls, mode
        self.n = 0
        self.log: list[str] = []

    def _maybe_bad(self, obs: Observation) -> Observation:
        self.n += 1
        if self.n in self.bad_calls:
            if self.mode == "raise":
                raise BadFrameError("truncated pixel frame")
            return Observation(np.zeros((8, 8, 3), np.uint8), obs.stamp)
        return obs

    def observe(self) -> Observation:
        self.log.append("observe")
        return self._maybe_bad(self.inner.observe())

    def step(self, v: float, w: float, duration: float) -> Observation:
        self.log.append("step")
        return self._maybe_bad(self.inner.step(v, w, duration))

    def stop(self) -> None:
        self.log.append("stop")
        self.inner.stop()


class SpyPolicy:
    """OnnxPolicy that refuses any image it should never have been given."""

    def __init__(self, inner: OnnxPolicy) -> None:
        self.inner = inner
        self.image_shape = inner.image_shape
        self.seen = 0

    @property
    def nonfinite_count(self) -> int:
        return self.inner.nonfinite_count

    def predict(self, current, subgoal):
        assert current.shape == (16, 16, 3) and np.asarray(current).dtype == np.uint8
        if not np.shares_memory(current, subgoal):  # a camera frame, not the zero bias's subgoal on itself
            self.seen += 1
        return self.inner.predict(current, subgoal)


@pytest.mark.parametrize("mode", ["raise", "wrong_shape"])
def test_bad_frames_are_counted_never_fed_to_the_network_and_the_robot_keeps_still(policy_path, mode):
    sim = FakeSim()
    robot = FlakyRobot(LocalRobot(sim), bad_calls={1, 3, 4}, mode=mode)
    policy = SpyPolicy(OnnxPolicy(policy_path))
    summary = run_repeat(robot, policy, corridor_route(), RepeatConfig(bad_frame_backoff_s=0.0))
    assert summary.completed and summary.bad_frames == 3
    # each bad frame is followed by a zero command before the robot is polled again
    frame_calls = 0
    for i, call in enumerate(robot.log):
        if call != "stop":
            frame_calls += 1
            if frame_calls in robot.bad_calls:
                assert robot.log[i + 1] == "stop", robot.log[: i + 2]
    assert policy.seen == summary.steps


def test_no_valid_frame_within_the_timeout_stops_the_run(policy_path):
    robot = FlakyRobot(LocalRobot(FakeSim()), bad_calls=set(range(2, 10_000)), mode="raise")
    summary = run_repeat(
        robot,
        OnnxPolicy(policy_path),
        corridor_route(),
        RepeatConfig(frame_timeout_s=0.2, bad_frame_backoff_s=0.01),
    )
    assert summary.status == "link_lost" and not summary.completed and summary.steps == 0
    assert "last rejected: truncated pixel frame" in summary.detail
    assert robot.log[-1] == "stop"


def test_an_exception_commands_zero_velocity_and_propagates(policy_path):
    class Broken:
        image_shape = (16, 16)
        nonfinite_count = 0

        def predict(self, current, subgoal):
            if not np.shares_memory(current, subgoal):  # the zero bias's pass over the route goes through
                raise RuntimeError("onnxruntime exploded")
            return np.zeros((2, 1), np.float32)

    robot = LocalRobot(FakeSim())
    with pytest.raises(RuntimeError, match="exploded"):
        run_repeat(robot, Broken(), corridor_route())
    assert robot.commands[-1] == (0.0, 0.0, 0.0)


def test_stop_event_interrupts_with_a_zero_command(policy_path):
    robot = LocalRobot(FakeSim())
    event = threading.Event()

    def log(record):
        if record.get("step") == 2:
            event.set()

    summary = run_repeat(robot, OnnxPolicy(policy_path), corridor_route(), log=log, stop_event=event)
    assert summary.status == "interrupted" and summary.steps == 3 and robot.commands[-1] == (0.0, 0.0, 0.0)


class KillingRobot:
    """A SimClient whose server is killed after ``kill_after`` steps and restarted where the robot stood."""

    def __init__(self, client: SimClient, handle, cfg: ServerConfig, kill_after: int, restart: bool) -> None:
        self.client, self.handle, self.cfg = client, handle, cfg
        self.kill_after, self.restart = kill_after, restart
        self.steps = 0
        self.restarter: threading.Thread | None = None

    @property
    def bad_frames(self) -> int:
        return self.client.bad_frames

    def observe(self):
        return self.client.observe()

    def stop(self):
        self.client.stop()

    def step(self, v, w, duration):
        obs = self.client.step(v, w, duration)
        self.steps += 1
        if self.steps == self.kill_after:
            self.handle.kill()  # SIGKILL: the server dies mid-route without a word
            if self.restart:
                factory = FakeSimAt(obs.pose[0], obs.stamp)  # a bridge restart: the robot has not moved
                self.restarter = threading.Thread(target=self._restart, args=(factory,), daemon=True)
                self.restarter.start()
        return obs

    def _restart(self, factory) -> None:
        time.sleep(0.3)
        self.handle = start_server_process(self.cfg, factory)


def _free_endpoint() -> str:
    with ServerThread(FakeSim()) as probe:
        return probe.endpoint


def test_server_killed_mid_route_and_restarted_the_repeat_stops_saying_so(policy_path):
    cfg = ServerConfig(bind=_free_endpoint(), poll_ms=20)
    handle = start_server_process(cfg, FakeSim)
    client = SimClient(cfg.bind, timeout_s=0.25, retries=60)  # restart takes longer than one timeout
    robot = KillingRobot(client, handle, cfg, kill_after=4, restart=True)
    try:
        summary = run_repeat(robot, OnnxPolicy(policy_path), corridor_route())
    finally:
        client.close()
        if robot.restarter is not None:
            robot.restarter.join(30)
        robot.handle.terminate()
    # the rebooted robot is somewhere else: the run ends rather than steering it from a stale view
    assert summary.status == "robot_restarted" and "robot restarted" in summary.detail
    assert client.timeouts >= 1 and client.session_changes == 1


def test_server_killed_for_good_the_repeat_stops_cleanly(policy_path):
    cfg = ServerConfig(bind=_free_endpoint(), poll_ms=20)
    handle = start_server_process(cfg, FakeSim)
    client = SimClient(cfg.bind, timeout_s=0.2, retries=2)
    robot = KillingRobot(client, handle, cfg, kill_after=3, restart=False)
    try:
        summary = run_repeat(robot, OnnxPolicy(policy_path), corridor_route())
    finally:
        client.close()
        handle.terminate()
    assert summary.status == "link_lost" and "no reply" in summary.detail and not summary.completed
    assert summary.steps == 2  # step 3 reached the server, then its zero command found nobody


def test_teach_then_repeat_over_zeromq_through_the_cli(policy_path, tmp_path, capsys):
    from vtr.cli import main
    from vtr.runtime.route import Route

    script = tmp_path / "corridor.json"
    script.write_text(
        json.dumps(
            {"start": {"x": 0.0, "y": 0.0, "yaw": 0.0}, "segments": [{"v": 0.25, "w": 0.0, "duration": 1.0}]}
        )
    )
    sim = FakeSim(x=0.7)
    with ServerThread(sim) as server:
        out = tmp_path / "route.npz"
        assert main(["teach", "--sim", server.endpoint, "--route", str(script), "--out", str(out)]) == 0
        route = Route.load(out)
        assert len(route) == 6 and route.spacing == {"rule": "steps", "dt": 0.1, "every": 2}
        np.testing.assert_allclose(route.poses[:, 0], [0.0, 0.05, 0.1, 0.15, 0.2, 0.25], atol=1e-9)
        assert route.commands.tolist() == [[0.25, 0.0]] * 5 + [[0.0, 0.0]]
        assert route.camera["width"] == 16 and route.map == "corridor" and route.name == "corridor"
        np.testing.assert_array_equal(route.images[2], render(0.1))
        capsys.readouterr()  # the sim stands at the route's end now; repeat resets it to the start
        log = tmp_path / "run.jsonl"
        argv = [
            "repeat",
            "--sim",
            server.endpoint,
            "--model",
            policy_path,
            "--route",
            str(out),
            "--log",
            str(log),
            "--json",
            "--profile",  # the fake policy steers on brightness, which light matching would even out
            "paper",
        ]
        assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["completed"] and summary["subgoals_reached"] == 6
    lines = [json.loads(line) for line in log.read_text().splitlines()]
    assert len(lines) == summary["steps"] + 1 and "summary" in lines[-1]
    assert lines[0]["pose"] == [0.0, 0.0, 0.0] and lines[0]["stamp"] == 0.0
    assert set(lines[0]) == LOG_KEYS and {"receive", "decode"} <= set(lines[0]["latency_ms"])


def test_teach_spacing_rules(tmp_path):
    from vtr.runtime.route_script import parse_route_script
    from vtr.runtime.teach import TeachConfig, teach

    script = parse_route_script(
        {"start": {"x": 0, "y": 0, "yaw": 0}, "segments": [{"v": 0.5, "w": 0, "duration": 1.0}]}
    )
    by_distance = teach(LocalRobot(FakeSim()), script, TeachConfig(spacing="distance", min_distance=0.19))
    np.testing.assert_allclose(by_distance.poses[:, 0], [0.0, 0.2, 0.4, 0.5], atol=1e-9)
    by_image = teach(LocalRobot(FakeSim()), script, TeachConfig(spacing="image", min_image_change=29.0))
    np.testing.assert_allclose(by_image.poses[:, 0], [0.0, 0.15, 0.3, 0.45, 0.5], atol=1e-9)
    with pytest.raises(ValueError, match="spacing"):
        TeachConfig(spacing="random")


def test_repeat_config_validation():
    with pytest.raises(ValueError, match="max_steps"):
        RepeatConfig(max_steps=0)
    with pytest.raises(ValueError, match="dt"):
        RepeatConfig(dt=-0.1)
    with pytest.raises(ValueError, match="frame_timeout_s"):
        RepeatConfig(frame_timeout_s=0)


def test_localise_option_starts_mid_route(policy_path):
    sim = FakeSim(x=0.2)
    cfg = RepeatConfig(controller=replace(ControllerConfig.before(), localise=True))
    records: list[dict] = []
    summary = run_repeat(LocalRobot(sim), OnnxPolicy(policy_path), corridor_route(), cfg, log=records.append)
    assert summary.completed and summary.localised_to == 4
    assert records[0]["from_subgoal"] == 0 and records[0]["jumped_to"] == [4]


def test_camera_at_the_wrong_resolution_never_reaches_the_network(policy_path):
    policy = SpyPolicy(OnnxPolicy(policy_path))
    with (
        ServerThread(FakeSim(h=8, w=8)) as server,
        SimClient(server.endpoint, 2.0, expect_shape=(16, 16)) as client,
    ):
        cfg = RepeatConfig(frame_timeout_s=0.3, bad_frame_backoff_s=0.02)
        summary = run_repeat(client, policy, corridor_route(), cfg)
        assert server.server.last_cmd == "stop"
    assert summary.status == "link_lost" and "image is 8x8, expected 16x16" in summary.detail
    assert policy.seen == 0 and summary.bad_frames >= 2 and client.bad_frames == summary.bad_frames


def test_cli_reports_bad_inputs_without_a_traceback(policy_path, tmp_path, capsys):
    from vtr.cli import main

    route = tmp_path / "route.npz"
    corridor_route(h=8, w=8).save(route)
    argv = ["repeat", "--sim", "tcp://127.0.0.1:1", "--model", policy_path, "--route", str(route)]
    assert main(argv) == 2
    assert "route images are 8x8 but the model takes 16x16" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text('{"start": {"x": 0, "y": 0, "yaw": 0}, "segments": [{"v": 3, "w": 0, "duration": 1}]}')
    assert (
        main(["teach", "--sim", "tcp://127.0.0.1:1", "--route", str(bad), "--out", str(tmp_path / "o.npz")])
        == 2
    )
    assert "v_max" in capsys.readouterr().err
    good = tmp_path / "good.json"
    good.write_text('{"start": {"x": 0, "y": 0, "yaw": 0}, "segments": [{"v": 0.1, "w": 0, "duration": 1}]}')
    argv = ["teach", "--sim", "tcp://127.0.0.1:1", "--route", str(good), "--out", str(tmp_path / "o.npz")]
    assert main([*argv, "--timeout", "0.05"]) == 2
    assert "no reply from tcp://127.0.0.1:1" in capsys.readouterr().err
    assert not (tmp_path / "o.npz").exists()


def test_teach_against_nothing_gives_up_after_one_round_of_tries():
    from vtr.runtime.robot import RobotError
    from vtr.runtime.route_script import parse_route_script
    from vtr.runtime.teach import teach

    script = parse_route_script(
        {"start": {"x": 0, "y": 0, "yaw": 0}, "segments": [{"v": 0.1, "w": 0, "duration": 1}]}
    )
    with SimClient("tcp://127.0.0.1:9", timeout_s=0.05, retries=2, setup_timeout_s=0.05) as client:
        with pytest.raises(RobotError, match="no reply .* to 'hello'"):
            teach(client, script)  # hello's tries only: reset is not tried again against nobody


def _settings(*argv: str):
    import argparse

    from vtr.runtime.daemon import add_arguments, config_from_settings
    from vtr.runtime.settings_cli import resolve

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    common = ["--sim", "tcp://127.0.0.1:5555", "--model", "m.onnx", "--route", "r.npz"]
    return config_from_settings(resolve(parser.parse_args([*common, *argv]), "repeat"))


def test_profiles_and_settings_reach_the_run_config():
    default = _settings()
    assert default.repeat.controller == ControllerConfig() and default.match_light
    assert default.start == "route" and not default.repeat.controller.localise
    paper = _settings("--profile", "paper")
    assert paper.repeat.controller == ControllerConfig.paper() and not paper.match_light  # Algorithm 1
    anywhere = _settings("--start", "anywhere", "--motion", "continuous", "--profile", "paper")
    assert anywhere.start == "here" and anywhere.repeat.controller.localise  # no reset, the route searched
    assert anywhere.repeat.controller.continuous and anywhere.repeat.controller.switching == "rules"
    assert (default.motion, paper.motion, anywhere.motion) == ("auto", "stop-and-go", "continuous")
    assert (
        _settings("--start", "here").start == "here"
        and not _settings("--start", "here").repeat.controller.localise
    )
    run = _settings(
        "--wait", "3", "--stop-distance", "0.3", "--slowdown-distance", "0.5", "--robot-radius", "0.2"
    )
    assert run.repeat.wait_s == 3.0
    assert (
        run.repeat.safety.stop_distance,
        run.repeat.safety.slowdown_distance,
        run.repeat.safety.radius,
    ) == (
        0.3,
        0.5,
        0.2,
    )


def test_auto_motion_is_continuous_only_on_a_robot_with_a_wall_clock():
    from vtr.runtime.daemon import motion_for_robot

    repeat = _settings().repeat
    assert motion_for_robot(repeat, "auto", "realtime").controller.continuous
    assert not motion_for_robot(repeat, "auto", "lockstep").controller.continuous
    assert not motion_for_robot(repeat, "auto", None).controller.continuous  # a robot that does not say
    fixed = _settings("--motion", "stop-and-go").repeat
    assert motion_for_robot(fixed, "stop-and-go", "realtime") is fixed  # asked for: kept on any robot
