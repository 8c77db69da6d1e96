"""A taught turn in place starts where the floor places the robot at the turn's pose (runtime.pivot): dev house
random:931 turned 77 mm short of its last turn, where the estimate had run a gap ahead, and every view of the
turn (a plain wall) matched as well there."""

from __future__ import annotations

import numpy as np
import pytest
from floor_fakes import CAM, floor_view

from vtr.runtime.controller import ControllerConfig
from vtr.runtime.decisions import Action
from vtr.runtime.follower import Follower
from vtr.runtime.pivot import PivotArrival
from vtr.runtime.side_offset import SideOffset

TILT = 0.3  # squares laid across the path at an angle (tests/runtime/test_arrival.py)
DRIVE, TURNS, GAP = 12, 2, 0.1  # subgoals 0-11 driven 0.1 m apart, then turned in place at subgoal 11


def route() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Views, poses, commands and held flags: a drive along x, then a turn in place of 0.3 rad a gap."""
    poses = np.array(
        [[GAP * k, 0.0, 0.0] for k in range(DRIVE)]
        + [[GAP * (DRIVE - 1), 0.0, 0.3 * t] for t in range(1, 1 + TURNS)]
    )
    views = np.stack([floor_view(x, tilt=TILT) for x in poses[:, 0]])
    commands = np.zeros((len(poses), 2))
    commands[: DRIVE - 1, 0] = 0.25
    commands[DRIVE - 1 : -1, 1] = 1.5
    held = np.zeros(len(poses), dtype=bool)
    held[DRIVE:] = True
    return views, poses, commands, held


def pivot() -> PivotArrival:
    views, poses, _, held = route()
    motion = np.diff(poses, axis=0)[:, [0, 2]]
    return PivotArrival(SideOffset(views, poses, CAM), motion, held)


def test_the_turn_s_pose_is_the_subgoal_where_the_teach_stopped_driving():
    # per gap: the turn's pose (subgoal 11) in the turn's gaps, none elsewhere (the last subgoal has no gap)
    assert pivot().pivot_of.tolist() == [-1] * (DRIVE - 1) + [DRIVE - 1] * TURNS + [-1]


@pytest.mark.parametrize("short", [0.03, 0.06, 0.12])
def test_the_floor_places_a_robot_short_of_the_turn_s_pose_on_the_drive_into_it(short):
    placed = pivot().short_of(floor_view(GAP * (DRIVE - 1) - short, tilt=TILT), DRIVE - 1, 0.025)
    assert placed == pytest.approx(DRIVE - 1 - short / GAP, abs=0.1)


def test_at_the_pose_or_half_a_step_short_of_it_the_turn_starts():
    p = pivot()
    assert p.short_of(floor_view(GAP * (DRIVE - 1), tilt=TILT), DRIVE - 1, 0.025) is None
    assert p.short_of(floor_view(GAP * (DRIVE - 1) - 0.01, tilt=TILT), DRIVE - 1, 0.025) is None


def test_a_turn_is_judged_until_it_starts_and_not_after_nor_past_the_search_s_span():
    short = floor_view(GAP * (DRIVE - 1) - 0.05, tilt=TILT)
    p = pivot()
    assert p.short_of(short, DRIVE - 1, 0.025) is not None
    p.started(DRIVE)  # the turn of gap DRIVE is the same turn
    assert p.short_of(short, DRIVE - 1, 0.025) is None
    p.reset()  # relocalised: asked again
    assert p.short_of(short, DRIVE - 1, 0.025) is not None
    p.commanded(0.25, 0.8)  # 20 cm driven on since, past the 15 cm searched: the reading was not borne out
    assert p.short_of(short, DRIVE - 1, 0.025) is None


def test_no_turn_is_judged_on_a_route_without_one_after_a_drive_nor_without_a_floor_registration():
    views, poses, _, held = route()
    motion = np.diff(poses, axis=0)[:, [0, 2]]
    short = floor_view(GAP * (DRIVE - 1) - 0.05, tilt=TILT)
    for p in (
        PivotArrival(SideOffset(views, poses, CAM), motion, np.zeros_like(held)),
        PivotArrival(None, motion, held),
    ):
        assert (p.pivot_of < 0).all() and p.short_of(short, DRIVE - 1, 0.025) is None
    assert PivotArrival(None, motion[:0], held[:1]).short_of(short, 0, 0.025) is None  # one subgoal


def test_the_follower_drives_on_to_the_turn_s_pose_where_the_estimate_got_there_early():
    views, poses, commands, _ = route()
    follower = Follower(
        views, ControllerConfig(zero_bias=0.0, obstruction=False), commands, poses, poses, camera=CAM
    )
    follower._step_m = 0.025
    follower.localiser.start_at(DRIVE - 0.5)  # the estimate half a gap into the turn
    short = follower.judge(floor_view(GAP * (DRIVE - 1) - 0.06, tilt=TILT)).decision
    assert short.action is Action.COMMAND and short.v_limit > 0 and short.index <= DRIVE - 1
    assert follower.estimate is not None and follower.estimate.position < DRIVE - 1
    follower.localiser.start_at(DRIVE - 0.5)
    there = follower.judge(floor_view(GAP * (DRIVE - 1), tilt=TILT)).decision
    assert there.action is Action.COMMAND and there.v_limit == 0.0  # the taught turn, on the spot
