"""The repeat loop over the real client when the link misbehaves: a bad reply to the zero command, a silent
robot, a rebooted robot (ends the run, or re-localises with --localise)."""

from __future__ import annotations

import numpy as np
import pytest
from runtime_fakes import FakeSim, build_velocitynet_onnx, corridor_route, run_repeat

from vtr.benchmarks.link_robot import DrivingPolicy, FakeRobot, good_reply, unreachable_route
from vtr.runtime.client import SimClient
from vtr.runtime.controller import ControllerConfig
from vtr.runtime.policy import OnnxPolicy
from vtr.runtime.repeater import RepeatConfig
from vtr.sim2d.server import ServerThread

# no stall guard and no lost test: these runs are about the link, on a route the robot cannot reach
NO_STALL = RepeatConfig(
    controller=ControllerConfig(stall_steps=0, lost_steps=0), max_steps=12, frame_timeout_s=1.0
)


def _repeat_against(behaviour):
    """Run the repeat loop against a FakeRobot answering with ``behaviour``; (robot, summary)."""
    robot = FakeRobot(behaviour)
    try:
        with SimClient(robot.endpoint, expect_shape=(16, 16)) as client:
            return robot, run_repeat(client, DrivingPolicy(), unreachable_route(), NO_STALL)
    finally:
        robot.close()


def test_a_bad_reply_to_the_zero_command_is_counted_and_the_run_goes_on():
    stops = {"n": 0}

    def behaviour(robot, req):
        if req.cmd == "stop" and robot.executed_steps:
            stops["n"] += 1
            if stops["n"] in (1, 4):  # the zero command after steps 1 and 3; its re-send is answered
                return [[b"{not json"]]
        return [good_reply(robot, req)]

    robot, summary = _repeat_against(behaviour)
    assert summary.status == "step_limit" and summary.steps == 12 and summary.bad_frames == 2
    cmds = [a.req.cmd for a in robot.commands()]
    first_bad = cmds.index("stop", cmds.index("step"))
    assert cmds[first_bad + 1] == "stop"  # the zero command is sent again before anything else


def test_a_silent_robot_gets_its_zero_command_within_half_a_second_and_the_run_ends_link_lost():
    def behaviour(robot, req):
        if req.cmd == "step" and len(robot.executed_steps) >= 3:
            robot.mute = True
        return [] if robot.mute else [good_reply(robot, req)]

    robot, summary = _repeat_against(behaviour)
    assert summary.status == "link_lost" and summary.steps == 3
    cmds = robot.commands()
    last_step = max(i for i, a in enumerate(cmds) if a.req.cmd == "step")
    after = [a for a in cmds[last_step + 1 :]]
    assert after and all(a.req.cmd == "stop" for a in after)  # never the step again
    assert after[0].t - cmds[last_step].t < 0.5


@pytest.fixture(scope="module")
def policy_path(tmp_path_factory):
    return build_velocitynet_onnx(str(tmp_path_factory.mktemp("model") / "tiny.onnx"))


class Rebooting:
    """A SimClient whose server restarts (new session, robot back at the start) after ``after`` steps."""

    def __init__(self, client: SimClient, server: ServerThread, after: int) -> None:
        self.client, self.server, self.after, self.steps = client, server, after, 0

    def observe(self):
        return self.client.observe()

    def stop(self):
        self.client.stop()

    def step(self, v, w, duration):
        obs = self.client.step(v, w, duration)
        self.steps += 1
        if self.steps == self.after:
            inner = self.server.server
            inner.session, inner.sim = "rebooted0001", FakeSim(x=0.15)  # same socket, a new life
        return obs


@pytest.mark.parametrize("localise", [False, True])
def test_a_rebooted_robot_ends_the_run_or_is_relocalised_and_never_gets_a_step_meant_for_its_old_life(
    policy_path, localise
):
    cfg = RepeatConfig(controller=ControllerConfig(localise=localise))
    with ServerThread(FakeSim()) as server, SimClient(server.endpoint, expect_shape=(16, 16)) as client:
        client.handshake()
        robot = Rebooting(client, server, after=3)
        summary = run_repeat(robot, OnnxPolicy(policy_path), corridor_route(), cfg)
        rebooted = server.server.sim
    if localise:
        assert summary.completed and summary.robot_restarts == 1
        assert rebooted.calls[0][0] == "step"  # the first thing it did was a step of the re-localised run
    else:
        assert summary.status == "robot_restarted" and "robot restarted" in summary.detail
        assert [c for c in rebooted.calls if c[0] == "step"] == []
    assert np.isfinite(summary.e_m)
