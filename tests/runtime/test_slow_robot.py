"""A robot whose step replies come just too late for the control period: every one is missed and a stop
follows it; the repeat ends as robot_too_slow after RepeatConfig.missed_replies of them in a row, instead of
creeping on until the step limit."""

from __future__ import annotations

import time

from vtr.benchmarks.link_robot import DrivingPolicy, FakeRobot, good_reply, unreachable_route
from vtr.runtime.client import SimClient
from vtr.runtime.controller import ControllerConfig
from vtr.runtime.missed_replies import MissedReplies
from vtr.runtime.repeater import RepeatConfig, Repeater, RepeatStatus
from vtr.runtime.robot import MissedReply

TIMEOUT_S = 0.2  # the client's wait beyond the step's 0.1 s
LATE_S = 0.35  # a step reply after 0.35 s: later than 0.1 + 0.2


def _slow_steps(late_after: int, fast_every: int = 0):
    """Step replies late from the ``late_after``-th step on (every ``fast_every``-th one in time when > 0)."""
    count = {"steps": 0}

    def behaviour(robot, req):
        if req.cmd == "step":
            count["steps"] += 1
            n = count["steps"]
            if n > late_after and not (fast_every and n % fast_every == 0):
                time.sleep(LATE_S)  # this robot answers late; its next request (the stop) is answered at once
        return [good_reply(robot, req)]

    return behaviour


def _repeat(behaviour, missed_replies: int, max_steps: int = 12):
    cfg = RepeatConfig(
        controller=ControllerConfig(stall_steps=0, lost_steps=0),
        max_steps=max_steps,
        frame_timeout_s=2.0,
        missed_replies=missed_replies,
    )
    robot = FakeRobot(behaviour)
    records = []
    try:
        with SimClient(robot.endpoint, timeout_s=TIMEOUT_S, expect_shape=(16, 16)) as client:
            rep = Repeater(client, DrivingPolicy(), unreachable_route(), config=cfg, on_step=records.append)
            return robot, rep.run(), records
    finally:
        robot.close()


def test_a_robot_answering_every_step_too_late_ends_as_robot_too_slow():
    robot, summary, records = _repeat(_slow_steps(late_after=2), missed_replies=3)
    assert summary.status is RepeatStatus.ROBOT_TOO_SLOW, summary
    assert summary.steps == 2 + 3  # two steps answered in time, then three missed in a row
    assert "robot too slow for the control period" in summary.detail
    assert "the last 3 step replies missed their 0.30 s wait" in summary.detail
    assert records[-1].status is RepeatStatus.ROBOT_TOO_SLOW
    cmds = [a.req.cmd for a in robot.commands()]
    assert cmds[-1] == "stop"
    # every missed step was followed by a stop before anything else
    assert all(cmds[i + 1] == "stop" for i, c in enumerate(cmds[:-1]) if c == "step" and i >= 0)


def test_without_the_limit_the_slow_robot_creeps_on_to_the_step_limit():
    """What happened before: every reply missed, a stop after each, on and on (the limit off shows it)."""
    _, summary, _ = _repeat(_slow_steps(late_after=0), missed_replies=0, max_steps=4)
    assert summary.status is RepeatStatus.STEP_LIMIT and summary.steps == 4 and summary.bad_frames >= 4


def test_replies_in_time_between_late_ones_keep_the_run_going():
    _, summary, _ = _repeat(_slow_steps(late_after=0, fast_every=2), missed_replies=2, max_steps=6)
    assert summary.status is RepeatStatus.STEP_LIMIT and summary.steps == 6


def test_the_counter_counts_misses_in_a_row_and_any_answer_resets_it():
    counter = MissedReplies(limit=2)

    def missed():
        raise MissedReply("no reply to 'step' within 0.40 s; the robot was sent a stop", 0.4)

    for outcome in (missed, lambda: "obs", missed):
        try:
            counter.watch(outcome)()
        except MissedReply:
            pass
    assert counter.in_row == 1 and counter.total == 2 and not counter.too_slow
    try:
        counter.watch(missed)()
    except MissedReply:
        pass
    assert counter.too_slow
    assert "the last 2 step replies missed their 0.40 s wait (the 0.10 s step + 0.30 s" in counter.describe(
        0.1
    )
    assert not MissedReplies(limit=0).too_slow
