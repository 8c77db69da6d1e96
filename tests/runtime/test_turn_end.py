"""A taught turn in place ends where the floor shows the robot turned to its end (runtime.turn_end): dev house
random:992 (seed 1) passed the taught heading with the estimate held just short of the turn's end, and the
replay of the taught turn spun it on the spot until the run ended `lost`."""

from __future__ import annotations

import math

import numpy as np
import pytest
from floor_fakes import CAM, floor_view

from vtr.runtime.controller import ControllerConfig
from vtr.runtime.decisions import Action
from vtr.runtime.follower import Follower
from vtr.runtime.kinematics import taught_motion
from vtr.runtime.side_offset import SideOffset
from vtr.runtime.turn_end import TurnEnd

TILT = 0.3  # squares laid at an angle to the path (tests/runtime/test_arrival.py)
DRIVE, TURNS, AFTER, GAP, STEP = 12, 2, 6, 0.1, 0.3  # a drive, a turn in place of 0.3 rad a gap, a drive on
PIVOT = GAP * (DRIVE - 1)
END = DRIVE - 1 + TURNS  # the subgoal where the turn ends
HEADING = STEP * TURNS  # the taught heading there


def route(after: int = AFTER, sign: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Views, poses and commands: along x, a turn in place at subgoal DRIVE - 1 (left, or right with ``sign``
    -1), then ``after`` subgoals on."""
    c, s = math.cos(sign * HEADING), math.sin(sign * HEADING)
    poses = np.array(
        [[GAP * k, 0.0, 0.0] for k in range(DRIVE)]
        + [[PIVOT, 0.0, sign * STEP * t] for t in range(1, 1 + TURNS)]
        + [[PIVOT + GAP * k * c, GAP * k * s, sign * HEADING] for k in range(1, 1 + after)]
    )
    views = np.stack([floor_view(x, y, yaw, tilt=TILT) for x, y, yaw in poses])
    commands = np.zeros((len(poses), 2))
    commands[: DRIVE - 1, 0] = 0.25
    commands[DRIVE - 1 : END, 1] = sign * 1.5
    commands[END:-1, 0] = 0.25
    return views, poses, commands


def turn_end(after: int = AFTER, floor: bool = True, sign: float = 1.0, held_to: int = END) -> TurnEnd:
    """The route's TurnEnd, the teach's turn taken as held into subgoals DRIVE .. ``held_to``."""
    views, poses, commands = route(after, sign)
    held = np.zeros(len(poses), dtype=bool)
    held[DRIVE : held_to + 1] = True
    motion = taught_motion(poses, commands, len(poses), 0.4)
    still = commands[:, 0] == 0
    return TurnEnd(SideOffset(views, poses, CAM) if floor else None, motion, held, still)


def at(heading: float, beside: float = 0.0, sign: float = 1.0) -> np.ndarray:
    """The view at the pivot (``beside`` m to the left of it, facing the taught heading) turned ``heading`` in
    the turn's direction (``sign``)."""
    yaw = sign * HEADING
    return floor_view(PIVOT - beside * math.sin(yaw), beside * math.cos(yaw), sign * heading, tilt=TILT)


def test_the_turn_s_end_is_known_for_each_subgoal_turned_into_where_a_drive_follows():
    assert turn_end().end_of.tolist() == [-1] * DRIVE + [END] * TURNS + [-1] * AFTER
    assert (turn_end(after=0).end_of < 0).all()  # a final turn in place: the end's own rules judge it


def test_a_turn_goes_on_where_the_teach_turned_on_with_no_translation_commanded():
    # dev house random:939 at 120 deg: the teach's pose moved 9 mm in the turn's last gap, which is then not
    # held; its command had no translation, and the teach turned 2.4 deg more there
    te = turn_end(held_to=END - 1)
    assert te.end_of.tolist() == [-1] * DRIVE + [END] * TURNS + [-1] * AFTER
    assert te.left[DRIVE - 1] == pytest.approx(HEADING) and te.left[END] == 0.0


@pytest.mark.parametrize("beside", [0.0, 0.05])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_the_floor_shows_the_robot_turned_to_the_end_or_past_it_and_not_short_of_it(beside, sign):
    te = turn_end(sign=sign)
    near = END - 0.1  # the estimate just short of the turn's end
    assert te.witness(at(HEADING, beside, sign), near, 0.15) == END
    assert te.witness(at(HEADING + 0.08, beside, sign), near, 0.15) == END  # turned past it
    assert te.witness(at(HEADING - 0.03, beside, sign), near, 0.15) == END  # within half a step of it
    assert te.witness(at(HEADING - 0.12, beside, sign), near, 0.15) is None  # short of it by most of a step
    assert te.witness(at(HEADING - 0.25, beside, sign), near, 0.15) is None


def test_only_in_a_turn_with_its_end_within_the_registration_s_reach():
    te = turn_end()
    end_view = at(HEADING)
    assert te.witness(end_view, DRIVE - 0.5, 0.15) is None  # on the drive before the turn
    assert te.witness(end_view, DRIVE - 1 + 0.1, 0.15) is None  # 0.57 rad of the turn left: beyond its reach
    assert te.witness(end_view, END + 0.5, 0.15) is None  # past the turn
    assert turn_end(floor=False).witness(end_view, END - 0.1, 0.15) is None  # no floor registration


def test_the_localiser_moves_the_belief_to_the_end_and_not_a_hair_short_of_it():
    views, poses, commands = route()
    follower = Follower(views, ControllerConfig(obstruction=False), commands, poses, poses, camera=CAM)
    loc = follower.localiser
    loc.start_at(END - 0.3)
    loc.update(at(HEADING))
    est = loc.at_least(END)
    assert est.position >= END and int(est.position) == END
    assert loc.belief.sum() == pytest.approx(1.0) and loc.belief[loc.cells < END].sum() == 0.0


def test_the_follower_drives_on_once_the_floor_shows_the_turn_s_end_where_the_views_do_not():
    views, poses, commands = route()
    follower = Follower(
        views, ControllerConfig(zero_bias=0.0, obstruction=False), commands, poses, poses, camera=CAM
    )
    follower._turn = 0.15  # turning at the taught rate
    follower.localiser.start_at(END - 0.6)
    short = follower.judge(at(HEADING - 0.3)).decision
    assert short.action is Action.COMMAND and short.v_limit == 0.0  # still the taught turn, on the spot
    follower.localiser.start_at(END - 0.6)  # the views have not placed the robot past the turn
    there = follower.judge(at(HEADING)).decision
    assert there.action is Action.COMMAND and there.v_limit > 0 and there.index > END
    assert follower.estimate is not None and follower.estimate.position >= END
