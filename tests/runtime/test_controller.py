"""The controller state machine and the daemon's loop contract with a scripted robot (Algorithm 1)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from runtime_fakes import run_repeat

from vtr.runtime.controller import Action, Controller, ControllerConfig, calibrate_e_m, consecutive_errors
from vtr.runtime.repeater import RepeatConfig
from vtr.runtime.robot import Observation
from vtr.runtime.route import Route

PAPER = ControllerConfig.paper()


def old(**changes) -> ControllerConfig:
    """The pre-matching defaults (raw error, route-wide e_m) with ``changes``: these tests use 4x4 flat images."""
    return replace(ControllerConfig.before(), **changes)


def flat(value: int, h: int = 4, w: int = 4) -> np.ndarray:
    return np.full((h, w, 3), value, dtype=np.uint8)


def subgoals(*values: int) -> np.ndarray:
    return np.stack([flat(v) for v in values])


def test_algorithm_1_decisions():
    c = Controller(subgoals(0, 100, 200), PAPER)
    assert c.e_m == 17.0
    d = c.decide(flat(50))
    assert d.action is Action.COMMAND and d.index == 0 and d.error == 50 and d.then_stop
    assert c.decide(flat(17)).action is Action.ADVANCE  # error == e_m switches (<=)
    assert c.index == 1
    d = c.decide(flat(17))  # the same image is then judged against the next subgoal
    assert d.action is Action.COMMAND and d.index == 1 and d.error == 83
    assert c.decide(flat(118)).action is Action.COMMAND  # 18 > 17: keep steering
    assert c.decide(flat(100)).action is Action.ADVANCE
    assert c.decide(flat(190)).action is Action.ADVANCE
    assert c.finished
    d = c.decide(flat(0))
    assert d.action is Action.FINISHED and math.isnan(d.error)


def test_calibrated_e_m_is_three_quarters_of_the_median_consecutive_error():
    images = subgoals(0, 10, 30, 60)  # consecutive errors 10, 20, 30
    np.testing.assert_allclose(consecutive_errors(images), [10, 20, 30])
    cfg = old()
    assert calibrate_e_m(images, cfg) == pytest.approx(15.0)
    assert Controller(images, cfg).e_m == pytest.approx(15.0)
    assert calibrate_e_m(images, old(calib_quantile=1.0, calib_fraction=1.0)) == pytest.approx(30)
    assert calibrate_e_m(images, old(e_m_max=4.0)) == 4.0
    assert calibrate_e_m(subgoals(5), old(e_m=12.0)) == 12.0  # one subgoal: the fixed value


def test_stall_guard_jumps_to_a_close_subgoal_ahead():
    cfg = old(e_m_mode="fixed", e_m=5.0, stall_steps=3, lookahead=3, jump_factor=2.0)
    c = Controller(subgoals(0, 20, 40, 60, 80), cfg)
    # stuck at 48: no progress towards subgoal 0, but subgoal 2 (error 8 <= 2 * e_m) is close
    assert [c.decide(flat(48)).action for _ in range(3)] == [Action.COMMAND] * 3
    d = c.decide(flat(48))
    assert d.action is Action.JUMP and d.index == 2 and d.note == "stall guard" and c.jumps == 1
    assert c.decide(flat(48)).action is Action.COMMAND and c.index == 2


def test_stall_guard_stops_when_nothing_is_close():
    cfg = old(e_m_mode="fixed", e_m=5.0, stall_steps=2, lookahead=2)
    c = Controller(subgoals(0, 20, 40, 60), cfg)
    c.decide(flat(200))
    c.decide(flat(200))
    d = c.decide(flat(200))
    assert d.action is Action.STALLED and "stopped falling" in d.note and c.stalled
    assert c.decide(flat(0)).action is Action.STALLED  # terminal


def test_stall_guard_accepts_a_plateau_next_to_the_subgoal():
    cfg = old(e_m_mode="fixed", e_m=5.0, stall_steps=2, lookahead=2, jump_factor=2.0)
    c = Controller(subgoals(0, 60, 120), cfg)
    # stuck at error 8: above e_m, within 2 * e_m, and nothing ahead is closer
    assert [c.decide(flat(8)).action for _ in range(2)] == [Action.COMMAND] * 2
    d = c.decide(flat(8))
    assert d.action is Action.ADVANCE and d.note == "accepted on plateau" and c.index == 1
    assert c.plateaus == 1 and not c.stalled
    # a plateau just outside 2 * e_m is still a stall
    c = Controller(subgoals(0, 60, 120), cfg)
    for _ in range(2):
        c.decide(flat(11))
    assert c.decide(flat(11)).action is Action.STALLED


def test_an_idle_policy_next_to_the_subgoal_is_accepted_at_once():
    # a noisy error that keeps "improving" by a hair: the stall counter never fills
    noisy = [9.0, 8.9, 8.8, 8.7, 8.6, 8.5, 8.4, 8.3]
    cfg = old(
        e_m_mode="fixed",
        e_m=5.0,
        stall_steps=10,
        lookahead=2,
        jump_factor=2.0,
        idle_steps=3,
        stall_min_improvement=0.05,
    )
    waits = Controller(subgoals(0, 60, 120), replace(cfg, idle_steps=0))
    for value in noisy:
        assert waits.decide(flat(int(round(value)))).action is Action.COMMAND
        waits.commanded(0.001, 0.0, 0.1)
    assert waits.index == 0  # without the idle rule the robot stands there
    c = Controller(subgoals(0, 60, 120), cfg)
    actions = []
    for value in noisy[:4]:
        actions.append(c.decide(flat(int(round(value)))).action)
        c.commanded(0.001, 0.0, 0.1)  # the policy barely moves the robot
    assert actions[:3] == [Action.COMMAND] * 3 and actions[3] is Action.ADVANCE
    assert c.index == 1 and c.plateaus == 1
    # a policy that still drives is not idle, and an idle one far from the subgoal is not accepted
    moving = Controller(subgoals(0, 60, 120), cfg)
    far = Controller(subgoals(0, 60, 120), cfg)
    for _ in range(4):
        assert moving.decide(flat(9)).action is Action.COMMAND
        moving.commanded(0.05, 0.0, 0.1)
        assert far.decide(flat(30)).action is Action.COMMAND
        far.commanded(0.0, 0.0, 0.1)
    assert moving.index == 0 and far.index == 0 and not far.stalled


def test_settling_keeps_steering_while_the_error_falls_under_e_m():
    cfg = old(e_m_mode="fixed", e_m=10.0, stall_steps=0, settle_steps=2)
    c = Controller(subgoals(0, 100), cfg)
    assert c.decide(flat(30)).action is Action.COMMAND
    d = c.decide(flat(8))  # under e_m and falling: one more command
    assert d.action is Action.COMMAND and d.note == "settling" and c.index == 0
    d = c.decide(flat(8))  # no longer falling: switch
    assert d.action is Action.ADVANCE and c.index == 1
    # at most settle_steps extra commands even while the error keeps falling
    c = Controller(subgoals(0, 100), cfg)
    actions = [c.decide(flat(v)).action for v in (9, 6, 3, 1)]
    assert actions == [Action.COMMAND, Action.COMMAND, Action.ADVANCE, Action.COMMAND]
    assert c.index == 1


def test_paper_config_is_algorithm_1():
    cfg = ControllerConfig.paper()
    assert (cfg.e_m_mode, cfg.e_m, cfg.stall_steps, cfg.settle_steps) == ("fixed", 17.0, 0, 0)
    assert not cfg.localise and not cfg.continuous


def test_progress_resets_the_stall_counter():
    cfg = old(e_m_mode="fixed", e_m=5.0, stall_steps=2)
    c = Controller(subgoals(0, 100), cfg)
    for value in (90, 80, 70, 60, 50, 40):  # slowly but steadily closer
        assert c.decide(flat(value)).action is Action.COMMAND


def test_localisation_starts_at_the_best_match_above_the_confidence_floor():
    cfg = old(e_m_mode="fixed", e_m=5.0, localise=True, stall_steps=0, settle_steps=0)
    c = Controller(subgoals(0, 50, 100, 150), cfg)
    d = c.decide(flat(98))
    assert d.action is Action.JUMP and d.index == 2 and c.localised_to == 2
    assert c.decide(flat(98)).action is Action.ADVANCE
    far = Controller(subgoals(0, 50, 100, 150), cfg)  # floor 3 * e_m = 15
    assert far.decide(flat(230)).action is Action.COMMAND and far.index == 0 and far.localised_to is None


def test_continuous_mode_does_not_stop_between_steps():
    c = Controller(subgoals(0, 100), old(e_m_mode="fixed", e_m=5.0, continuous=True))
    assert c.decide(flat(60)).then_stop is False


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"e_m_mode": "auto"}, "e_m_mode"),
        ({"e_m": 0.0}, "e_m must"),
        ({"e_m": float("nan")}, "e_m must"),
        ({"calib_quantile": 1.5}, "calib_quantile"),
        ({"e_m_min": 10.0, "e_m_max": 5.0}, "e_m_max"),
        ({"stall_steps": -1}, "stall_steps"),
        ({"lookahead": 0}, "lookahead"),
        ({"localise_max_error": -1.0}, "localise_max_error"),
    ],
)
def test_controller_config_validation(kwargs, fragment):
    with pytest.raises(ValueError, match=fragment):
        ControllerConfig(**kwargs)


def test_controller_refuses_wrong_images():
    with pytest.raises(ValueError, match="uint8"):
        Controller(np.zeros((2, 4, 4, 3), dtype=np.float32), old())
    with pytest.raises(ValueError, match=r"expected \(4, 4, 3\)"):
        Controller(subgoals(0, 1), old()).decide(flat(0, 8, 8))


# ---------------------------------------------------------------------------------------- loop contract


class ScriptedRobot:
    """observe() returns frame 0; each step() returns the next scripted frame. Records every call."""

    def __init__(self, frames: list[np.ndarray]) -> None:
        self.frames = frames
        self.i = 0
        self.calls: list[tuple] = []

    def observe(self) -> Observation:
        self.calls.append(("observe",))
        return Observation(self.frames[self.i], float(self.i))

    def step(self, v: float, w: float, duration: float) -> Observation:
        self.calls.append(("step", v, w, duration))
        self.i += 1
        return Observation(self.frames[self.i], float(self.i))

    def stop(self) -> None:
        self.calls.append(("stop",))


class SpyPolicy:
    image_shape = (4, 4)
    nonfinite_count = 0

    def __init__(self) -> None:
        self.inputs: list[tuple[int, int]] = []

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        self.inputs.append((int(current.image[0, 0, 0]), int(subgoal.image[0, 0, 0])))  # frames
        return np.array([[0.3, 0.1], [-0.2, 0.0]], dtype=np.float32)


def flat_route(*values: int) -> Route:
    n = len(values)
    return Route(images=subgoals(*values), poses=np.full((n, 3), np.nan), commands=np.zeros((n, 2)))


def test_loop_contract_command_then_zero_switch_at_e_m_finish_after_l_subgoals():
    route = flat_route(0, 100, 200)
    robot = ScriptedRobot([flat(50), flat(17), flat(117), flat(195)])
    policy = SpyPolicy()
    records: list[dict] = []
    summary = run_repeat(robot, policy, route, RepeatConfig(controller=PAPER), log=records.append)
    # the first predicted (v, w) for 0.1 s, then zero; one command per image above e_m
    assert robot.calls == [
        ("observe",),
        ("step", pytest.approx(0.3), pytest.approx(-0.2), 0.1),
        ("stop",),
        ("step", pytest.approx(0.3), pytest.approx(-0.2), 0.1),
        ("stop",),
        ("step", pytest.approx(0.3), pytest.approx(-0.2), 0.1),
        ("stop",),
        ("stop",),  # the final zero command when the loop ends
    ]
    # (current, subgoal) pairs the network saw: an error of exactly 17 switches, and the same image is
    # then steered towards the next subgoal
    assert policy.inputs == [(50, 0), (17, 100), (117, 200)]
    steps = [r for r in records if "step" in r]
    assert [(r["from_subgoal"], r["subgoal"], r["advanced"], r["error"]) for r in steps] == [
        (0, 0, 0, 50),
        (0, 1, 1, 83),
        (1, 2, 1, 83),
    ]
    assert summary.completed and summary.status == "finished"
    assert summary.steps == 3 and summary.subgoals_reached == 3 == summary.subgoals_total


def test_continuous_loop_sends_no_zero_between_steps():
    route = flat_route(0, 100)
    robot = ScriptedRobot([flat(60), flat(30), flat(0), flat(100)])
    cfg = RepeatConfig(
        controller=old(e_m_mode="fixed", e_m=17.0, stall_steps=0, settle_steps=0, continuous=True)
    )
    summary = run_repeat(robot, SpyPolicy(), route, cfg)
    names = [c[0] for c in robot.calls]
    assert names == ["observe", "step", "step", "step", "stop"] and summary.completed


def test_step_limit_stops_a_lost_robot():
    route = flat_route(0, 100)
    robot = ScriptedRobot([flat(250)] * 10)
    summary = run_repeat(robot, SpyPolicy(), route, RepeatConfig(controller=PAPER, max_steps=4))
    assert summary.status == "step_limit" and summary.steps == 4 and not summary.completed
    assert robot.calls[-1] == ("stop",)


def test_stall_in_the_loop_stops_with_a_reason():
    route = flat_route(0, 100)
    robot = ScriptedRobot([flat(250)] * 10)
    cfg = RepeatConfig(controller=old(e_m_mode="fixed", e_m=5.0, stall_steps=3))
    summary = run_repeat(robot, SpyPolicy(), route, cfg)
    assert (
        summary.status == "stalled" and "stopped falling" in summary.detail and robot.calls[-1] == ("stop",)
    )


def test_the_default_plateau_bound_is_two_and_a_half_thresholds():
    from vtr.runtime.matching import MatchConfig

    cfg = ControllerConfig(match=MatchConfig.paper(), e_m_mode="fixed", e_m=5.0, stall_steps=2, lookahead=2)
    assert cfg.jump_factor == 2.5 and ControllerConfig.before().jump_factor == 2.0
    for factor, expected in ((2.5, Action.ADVANCE), (2.0, Action.STALLED)):
        c = Controller(subgoals(0, 60, 120), replace(cfg, jump_factor=factor))
        for _ in range(2):
            c.decide(flat(11))  # stuck at 2.2 thresholds
        assert c.decide(flat(11)).action is expected
