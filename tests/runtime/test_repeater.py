"""The Repeater step by step: records, events, how a run ends, and the checks made before it starts."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from vtr.runtime.contracts import Observation, Policy, Robot, RobotLimits
from vtr.runtime.controller import Action, Controller, ControllerConfig
from vtr.runtime.repeater import RepeatConfig, Repeater, RepeatStatus, StepRecord
from vtr.runtime.robot import RobotError
from vtr.runtime.route import Route

PAPER = ControllerConfig.paper()


def flat(value: int) -> np.ndarray:
    return np.full((4, 4, 3), value, dtype=np.uint8)


def flat_route(*values: int, dt: float = 0.1) -> Route:
    n = len(values)
    images = np.stack([flat(v) for v in values])
    return Route(images=images, poses=np.zeros((n, 3)), commands=np.zeros((n, 2)), dt=dt)


class Frames:
    """observe() shows frame 0; each step() the next; ``fail_at`` raises that error on that step."""

    def __init__(self, values: list[int], fail_at: int | None = None, error: Exception | None = None) -> None:
        self.values, self.i, self.fail_at, self.error = values, 0, fail_at, error
        self.calls: list[str] = []

    def _obs(self) -> Observation:
        return Observation(flat(self.values[self.i]), float(self.i), pose=(float(self.i), 0.0, 0.0))

    def observe(self) -> Observation:
        self.calls.append("observe")
        return self._obs()

    def step(self, v: float, w: float, duration: float) -> Observation:
        self.calls.append("step")
        self.i += 1
        if self.i == self.fail_at:
            raise self.error  # type: ignore[misc]
        return self._obs()

    def stop(self) -> None:
        self.calls.append("stop")


class Constant:
    image_shape = (4, 4)

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        return np.array([[0.2, 0.0], [0.1, 0.0]], dtype=np.float32)


def test_fakes_satisfy_the_protocols():
    assert isinstance(Frames([0]), Robot) and isinstance(Constant(), Policy)


def test_step_by_step_records_commands_events_and_the_terminal_record():
    seen: list[StepRecord] = []
    robot = Frames([50, 17, 117, 195])
    rep = Repeater(
        robot, Constant(), flat_route(0, 100, 200), config=RepeatConfig(PAPER), on_step=seen.append
    )
    first = rep.step()
    assert first.commanded and first.action is Action.COMMAND and first.events == ()
    assert (first.step, first.from_subgoal, first.subgoal, first.error) == (0, 0, 0, 50)
    assert (first.v, first.w) == pytest.approx((0.2, 0.1)) and first.pose == (0.0, 0.0, 0.0)
    assert {"error", "policy", "compute", "robot", "total"} <= set(first.latency_ms)
    second = rep.step()  # 17 is within e_m of subgoal 0: the controller advances by itself
    assert [(e.action, e.index) for e in second.events] == [(Action.ADVANCE, 1)]
    assert (second.from_subgoal, second.subgoal, second.advanced) == (0, 1, 1)
    summary = rep.run()
    last = seen[-1]
    assert last.status is RepeatStatus.FINISHED and not last.commanded and (last.v, last.w) == (0.0, 0.0)
    assert [e.index for e in last.events] == [3] and last.pose == (3.0, 0.0, 0.0)
    assert summary.completed and summary.steps == 3 and len(seen) == 4
    assert robot.calls[-1] == "stop" and summary.to_dict()["status"] == "finished"
    with pytest.raises(RuntimeError, match="ended"):
        rep.step()


def test_a_robot_error_names_how_the_run_ended_and_stops_the_robot():
    class Restarted(RobotError):
        status = "robot_restarted"

    for error, status in (
        (RobotError("no reply"), "robot_error"),
        (Restarted("new session"), "robot_restarted"),
    ):
        robot = Frames([250] * 5, fail_at=2, error=error)
        summary = Repeater(robot, Constant(), flat_route(0, 100), config=RepeatConfig(PAPER)).run()
        assert summary.status == status and summary.detail == str(error) and summary.steps == 1
        assert robot.calls[-1] == "stop"


def test_run_takes_a_step_limit():
    rep = Repeater(Frames([250] * 10), Constant(), flat_route(0, 100), config=RepeatConfig(PAPER))
    summary = rep.run(max_steps=3)
    assert summary.status is RepeatStatus.STEP_LIMIT and summary.steps == 3
    with pytest.raises(ValueError, match="max_steps"):
        Repeater(Frames([0]), Constant(), flat_route(0), config=RepeatConfig(PAPER)).run(max_steps=-1)


def test_a_controller_can_be_handed_in_and_is_the_one_used():
    route = flat_route(0, 100)
    controller = Controller(route.images, replace(PAPER, e_m=60.0))
    rep = Repeater(Frames([80, 30, 100]), Constant(), route, controller)
    summary = rep.run()
    assert rep.controller is controller and summary.completed and controller.finished and summary.steps == 2


def test_the_taught_prior_blends_the_taught_command_into_the_policys():
    n = 3
    route = Route(
        images=np.stack([flat(v) for v in (0, 100, 200)]),
        poses=np.zeros((n, 3)),
        commands=np.array([[0.4, 0.6], [0.0, 0.0], [0.0, 0.0]]),
        dt=0.1,
    )
    cfg = replace(PAPER, taught_prior=0.25)
    sent: list[StepRecord] = []
    # frame 0 matches subgoal 0 (no command into it: the policy alone), then subgoal 1 is steered to
    rep = Repeater(
        Frames([0, 5, 150]),
        Constant(),
        route,
        Controller(route.images, cfg, route.commands),
        config=RepeatConfig(cfg),
        on_step=sent.append,
    )
    rep.step()
    first = sent[-1]
    assert first.subgoal == 1 and first.commanded
    # (1 - 0.25) * policy (0.2, 0.1) + 0.25 * taught (0.4, 0.6)
    assert first.v == pytest.approx(0.75 * 0.2 + 0.25 * 0.4) and first.w == pytest.approx(
        0.75 * 0.1 + 0.25 * 0.6
    )
    off = Repeater(Frames([0, 5, 150]), Constant(), route, config=RepeatConfig(PAPER), on_step=sent.append)
    off.step()
    assert (sent[-1].v, sent[-1].w) == pytest.approx((0.2, 0.1))


class Biased:
    """Like a network in a world unlike its training houses: on the subgoal itself it still says "turn"."""

    image_shape = (4, 4)

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        gap = float(subgoal.image[0, 0, 0]) - float(current.image[0, 0, 0])  # toward the subgoal's grey level
        return np.array([[0.001 * gap + 0.03], [0.15]], dtype=np.float32)


def test_zero_bias_takes_the_policys_command_on_the_subgoal_itself_off_every_command_toward_it():
    route = flat_route(0, 100, 200)
    sent: list[StepRecord] = []
    cfg = replace(PAPER, zero_bias=1.0)
    rep = Repeater(Frames([40, 60, 250]), Biased(), route, config=RepeatConfig(cfg), on_step=sent.append)
    rep.step()  # grey 40 is 40 from subgoal 0, above e_m = 17: steer toward it
    assert sent[-1].subgoal == 0
    assert sent[-1].v == pytest.approx(0.001 * -40) and sent[-1].w == pytest.approx(0.0, abs=1e-7)
    half = Repeater(
        Frames([40, 40]),
        Biased(),
        route,
        config=RepeatConfig(replace(cfg, zero_bias=0.5)),
        on_step=sent.append,
    )
    half.step()
    assert sent[-1].v == pytest.approx(0.001 * -40 + 0.015) and sent[-1].w == pytest.approx(0.075)
    off = Repeater(Frames([40, 40]), Biased(), route, config=RepeatConfig(PAPER), on_step=sent.append)
    off.step()
    assert sent[-1].w == pytest.approx(0.15)  # the drift that drove the robot off its first subgoal
    with pytest.raises(ValueError, match="zero_bias is a weight"):
        ControllerConfig(zero_bias=1.5)


def test_commands_stay_within_the_models_and_the_robots_limits_after_the_zero_bias():
    """The example room: the network at +0.5 m/s (its bound), its zero at -0.03, so the corrected command asked for
    0.53 m/s, the link refused it and the run ended with an error. It is clipped to the tighter bounds now."""

    class AtLimit(Biased):
        class meta:  # noqa: N801 - stands in for ModelMeta
            v_max, w_max, dt = 0.5, 1.0, 0.1

        def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
            same = np.shares_memory(current, subgoal)
            return np.array([[-0.03 if same else 0.5], [-0.2 if same else 0.95]], dtype=np.float32)

    class Announcing(Frames):
        limits = RobotLimits(v_max=0.4, w_max=2.0)

    sent: list[StepRecord] = []
    cfg = RepeatConfig(replace(PAPER, zero_bias=1.0))
    Repeater(Frames([40, 40]), AtLimit(), flat_route(0, 100), config=cfg, on_step=sent.append).step()
    assert (sent[-1].v, sent[-1].w) == pytest.approx((0.5, 1.0))  # not 0.53 and 1.15
    Repeater(Announcing([40, 40]), AtLimit(), flat_route(0, 100), config=cfg, on_step=sent.append).step()
    assert (sent[-1].v, sent[-1].w) == pytest.approx((0.4, 1.0))  # the robot's v bound is the tighter


def test_route_and_model_must_agree_on_dt_and_image_size():
    class WithMeta(Constant):
        class meta:  # noqa: N801 - stands in for ModelMeta
            dt = 0.2

    with pytest.raises(ValueError, match="dt = 0.1 s but the model was trained for dt = 0.2 s"):
        Repeater(Frames([0]), WithMeta(), flat_route(0, 100))
    assert Repeater(Frames([0]), WithMeta(), flat_route(0, 100, dt=0.2), config=RepeatConfig(PAPER)).dt == 0.2

    class Larger(Constant):
        image_shape = (8, 8)

    with pytest.raises(ValueError, match="route images"):
        Repeater(Frames([0]), Larger(), flat_route(0))


def test_an_unexpected_exception_stops_the_robot_and_propagates():
    robot = Frames([250] * 5, fail_at=1, error=ZeroDivisionError("bug"))
    rep = Repeater(robot, Constant(), flat_route(0, 100), config=RepeatConfig(PAPER))
    with pytest.raises(ZeroDivisionError):
        rep.run()
    assert robot.calls[-1] == "stop" and rep.done


def test_every_status_has_a_distinct_value():
    values = [s.value for s in RepeatStatus]
    assert len(set(values)) == len(values) == 11
    assert RepeatStatus("link_lost") is RepeatStatus.LINK_LOST
    assert RepeatStatus(Action.BLOCKED.value) is RepeatStatus.BLOCKED  # a BLOCKED decision ends as blocked


def test_a_failing_on_step_callback_stops_the_robot_and_propagates():
    def broken(record: StepRecord) -> None:
        raise OSError("disk full")

    robot = Frames([250] * 5)
    rep = Repeater(robot, Constant(), flat_route(0, 100), config=RepeatConfig(PAPER), on_step=broken)
    with pytest.raises(OSError, match="disk full"):
        rep.run()
    assert robot.calls[-1] == "stop" and rep.done and rep.steps == 1


def test_speed_scales_every_command_alike_and_gives_the_run_as_many_more_steps():
    seen: list[StepRecord] = []
    route = flat_route(0, 100, 200)
    full = Repeater(Frames([250] * 3), Constant(), route, config=RepeatConfig(PAPER))
    half = Repeater(
        Frames([250] * 3), Constant(), route, config=RepeatConfig(PAPER, speed=0.5), on_step=seen.append
    )
    half.step()
    assert (seen[-1].v, seen[-1].w) == pytest.approx((0.1, 0.05))  # the same arc (v / w), half as fast
    assert half.max_steps == 2 * full.max_steps
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(ValueError, match="speed"):
            RepeatConfig(speed=bad)
