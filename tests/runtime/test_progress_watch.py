"""runtime.progress_watch: images and commanded translation since the last evidence of where the robot is."""

from __future__ import annotations

import numpy as np
import pytest

from vtr.runtime.progress_watch import PROGRESS_GAPS, STALL_WINDOWS, STAND_WINDOWS, EndWatch, ProgressWatch


def test_the_image_budget_is_the_window_s_images_times_stall_windows():
    assert ProgressWatch(16.0).stall_images == int(STALL_WINDOWS * 16)


def test_images_without_evidence_run_out():
    watch = ProgressWatch(2.0)
    assert watch.judge(3.0, matched=False, window_m=1.0) is None  # the first view sets the reach
    notes = [watch.judge(3.0, matched=False, window_m=1.0) for _ in range(watch.stall_images)]
    assert notes[:-1] == [None] * (watch.stall_images - 1)
    assert notes[-1] == f"no progress past 3.00 for {watch.stall_images} images"


def test_travel_past_the_window_runs_out_before_the_images():
    watch = ProgressWatch(100.0)
    watch.judge(3.0, matched=False, window_m=0.5)
    watch.commanded(0.45, 1.0)
    assert watch.judge(3.0, matched=False, window_m=0.5) is None
    watch.commanded(-0.1, 1.0)  # backwards counts too: 0.55 m
    note = watch.judge(3.0, matched=False, window_m=0.5)
    assert note is not None and "0.55 m driven" in note and "0.50 m" in note


def test_progress_counts_afresh():
    watch = ProgressWatch(100.0)
    watch.judge(3.0, matched=False, window_m=0.5)
    watch.commanded(0.45, 1.0)
    assert watch.judge(3.0 + PROGRESS_GAPS, matched=False, window_m=0.5) is None
    assert watch.travel == 0.0 and watch.since == 0
    watch.commanded(0.45, 1.0)
    assert watch.judge(3.0 + PROGRESS_GAPS, matched=False, window_m=0.5) is None  # 0.45 m of 0.5: not yet


def test_a_matching_view_lets_the_robot_stand_but_not_drive_on_without_progress():
    """The example room's arc with the floor model: past the end the view matched the last-but-one subgoal
    under its threshold at every image, the estimate held half a gap short, and the robot crept on (10 cm
    past the end by the step limit) because each match counted as evidence afresh. A match is evidence of
    where the robot is, not that driving on gets it anywhere: it resets the images, not the travel."""
    watch = ProgressWatch(2.0)
    watch.judge(3.0, matched=False, window_m=0.5)
    for _ in range(
        watch.stand_images - 1
    ):  # standing with the view matched: past the images without evidence
        assert watch.judge(3.0, matched=True, window_m=0.5) is None
    assert watch.since == 0 and watch.stall_images < watch.stand_images - 1
    watch = ProgressWatch(2.0)
    watch.judge(3.0, matched=False, window_m=0.5)
    notes = []
    for _ in range(12):
        watch.commanded(0.05, 1.0)
        notes.append(watch.judge(3.1, matched=True, window_m=0.5))
    assert notes[:10] == [None] * 10 and notes[10] is not None and "0.55 m driven" in notes[10]


def test_a_matching_view_does_not_let_the_robot_stand_for_ever():
    """Held-out house random:8046 (session 25): at a taught turn the view matched subgoal 29 under its
    threshold, the estimate held at 28.5, VelocityNet commanded nothing, and the robot stood until the step
    limit (280 images). Standing where the views place it is allowed, for ``stand_images``, not for ever."""
    watch = ProgressWatch(2.0)
    assert watch.stand_images == int(STAND_WINDOWS * 2.0) > watch.stall_images
    watch.judge(28.5, matched=False, window_m=0.5)
    notes = [watch.judge(28.5, matched=True, window_m=0.5) for _ in range(watch.stand_images)]
    assert notes[:-1] == [None] * (watch.stand_images - 1)
    assert notes[-1] == f"no progress past 28.50 for {watch.stand_images} images, views matching or not"


def test_rocking_over_the_same_stretch_is_no_progress():
    """Set 12's gen_1317 on a wall-clock robot (session 26): at a taught turn in place the estimate advanced
    to 101, a matching view placed it back at 100, and each advance counted as progress afresh: the robot
    rocked there for 750 steps until the step limit. Only ground the estimate never reached is progress."""
    watch = ProgressWatch(2.0)
    watch.judge(100.0, matched=False, window_m=10.0)
    notes = []
    for _ in range(watch.stand_images):
        notes.append(watch.judge(101.0, matched=False, window_m=10.0))
        notes.append(watch.judge(100.0, matched=True, window_m=10.0))
    fired = [i for i, n in enumerate(notes) if n is not None]
    assert fired and fired[0] == watch.stand_images  # 101 was new ground once, at the first image
    assert (
        notes[fired[0]] == f"no progress past 101.00 for {watch.stand_images} images, views matching or not"
    )


def test_no_more_than_the_route_has_left_is_driven_without_progress():
    """Dev house random:935 at an 80 deg / 0.45 m camera: the robot passed 2 mm from the last pose with the view
    1.4 thresholds off, the estimate held 1.1-1.3 gaps short, and the robot drove on 0.27 m into a wall
    (`collided`), well inside the window's 0.25 m of driving without progress. Past the route's end there is
    nothing the views can follow: what the route has left from the furthest the views placed the robot,
    a gap for the estimate's lag and the 5 cm past the end the floor registration still searches
    (``PAST_END_M``) is all it may drive so."""
    route_m = np.array([0.0, 0.05, 0.1, 0.15, 0.2])  # 5 cm gaps, the last subgoal at 4
    for end_cap, expect_after in ((False, 6), (True, 3)):
        watch = ProgressWatch(100.0, route_m if end_cap else None)
        assert watch.judge(3.0, matched=False, window_m=0.25) is None  # 0.05 m of route left from here
        notes = []
        for _ in range(8):
            watch.commanded(0.4, 0.1)  # 4 cm a step, the estimate held
            notes.append(watch.judge(3.0, matched=False, window_m=0.25))
        fired = next(i for i, n in enumerate(notes) if n is not None) if any(notes) else None
        assert fired == expect_after  # the window: 0.28 m driven; the end: 0.16 m, past 0.05 + 0.05 + 0.05
    assert notes[3] == "no progress past 3.00 over 0.16 m driven (the route had 0.05 m left)"
    # mid-route the window decides, as before
    watch = ProgressWatch(100.0, np.arange(0.0, 2.0, 0.05))
    watch.judge(3.0, matched=False, window_m=0.25)
    watch.commanded(0.24, 1.0)
    assert watch.judge(3.0, matched=False, window_m=0.25) is None


def test_a_match_back_along_the_route_measures_progress_from_there():
    watch = ProgressWatch(100.0)
    watch.judge(5.0, matched=False, window_m=0.5)
    assert watch.judge(4.0, matched=True, window_m=0.5) is None and watch.reach == 4.0  # placed back
    watch.commanded(0.4, 1.0)
    assert watch.judge(4.0 + PROGRESS_GAPS, matched=False, window_m=0.5) is None and watch.travel == 0.0


def test_a_small_move_back_and_forth_is_no_progress():
    watch = ProgressWatch(2.0)
    watch.judge(3.0, matched=False, window_m=10.0)
    for i in range(watch.stall_images - 1):
        assert watch.judge(3.0 + (PROGRESS_GAPS / 2) * (i % 2), matched=False, window_m=10.0) is None
    assert watch.judge(3.0, matched=False, window_m=10.0) is not None


def _end_watch(held: np.ndarray | None = None) -> EndWatch:
    """5 subgoals on a straight, the last gaps 0.05 m (``held``: as if the teach had turned in place into
    those subgoals instead, a turn counted at 0.2 m a radian)."""
    motion = np.array([[0.1, 0.0], [0.1, 0.0], [0.05, 0.0], [0.05, 0.0]])
    if held is not None:
        motion[held[1:]] = (0.0, 0.25)
    return EndWatch(
        np.concatenate([[0.0], np.cumsum(np.hypot(motion[:, 0], 0.2 * motion[:, 1]))]), motion, held
    )


def test_the_route_left_is_interpolated_between_subgoals():
    watch = _end_watch()
    assert watch.left_from(4.0) == pytest.approx(0.0)
    assert watch.left_from(3.5) == pytest.approx(0.025)
    assert watch.left_from(1.0) == pytest.approx(0.2)
    assert watch.left_from(9.0) == pytest.approx(0.0) and watch.left_from(-1.0) == pytest.approx(0.3)


def test_driving_further_than_the_route_had_left_at_the_end_runs_out():
    watch = _end_watch()
    watch.commanded(3.0, 0.0, 0.1, 0.3)  # before the end: not counted
    assert (
        watch.judge(2.6, at_end=False, matched=True) is None and watch.start is None
    )  # a match near the end
    assert watch.judge(3.0, at_end=True, matched=False) is None  # 0.05 m of route left from here
    watch.commanded(0.4, 0.0, 0.1, 0.04)
    assert watch.judge(3.4, at_end=False, matched=False) is None  # 0.04 m driven: still on the route
    watch.commanded(-0.2, 0.0, 0.1, 0.02)  # backwards counts too
    note = watch.judge(3.6, at_end=True, matched=False)
    assert note == (
        "drove 0.06 m and turned 0 deg since the views placed it at the route's end (the route had 0.05 m and "
        "0 deg left)"
    )


def test_a_view_back_along_the_route_counts_afresh():
    watch = _end_watch()
    watch.judge(3.5, at_end=True, matched=True)
    watch.commanded(0.2, 0.0, 0.1, 0.02)
    assert watch.judge(1.5, at_end=False, matched=False) is None and watch.start is None  # placed back
    assert watch.judge(3.5, at_end=True, matched=False) is None  # counting afresh needs a match again
    assert watch.start is None


def test_without_a_match_near_the_end_travel_decides_nothing():
    """Dev gen_117 (re-coloured floor): the estimate reached the end on the commanded motion alone, every view
    1.4-1.9 thresholds off, 0.32 m from the end. Travel there is no evidence of the end."""
    watch = _end_watch()
    assert watch.judge(1.5, at_end=False, matched=True) is None  # a match, but before the end's zone
    assert watch.judge(3.5, at_end=True, matched=False) is None
    watch.commanded(1.0, 0.0, 1.0, 1.0)
    assert watch.judge(3.6, at_end=True, matched=False) is None and watch.start is None
    assert watch.judge(3.7, at_end=True, matched=True) is None  # now armed: 0.015 m of route left
    watch.commanded(0.2, 0.0, 0.1, 0.02)
    assert watch.judge(3.7, at_end=True, matched=False) is not None


def test_a_route_ending_with_a_turn_in_place_ends_when_the_taught_turn_is_turned():
    """Dev gen_176 (moved furniture): the views placed the robot at the end of a final turn in place, a
    quarter gap short, and no view matched there; the robot, replaying the taught turn, spun whole turns. The
    turn counts as the localiser counts it (0.2 m a radian), and the whole turn is the end's zone: a match
    anywhere in it arms the watch."""
    held = np.array([False, False, True, True, True])  # the teach turned in place from subgoal 1 on
    watch = _end_watch(held)
    assert watch.zone_from == 1.0  # the turn's start, not 2 gaps before the end
    assert watch.judge(1.6, at_end=False, matched=True) is None  # a match in the turn: the end's place
    assert watch.judge(3.75, at_end=True, matched=False) is None  # a quarter gap left: 0.0625 rad
    watch.commanded(0.0, 0.5, 0.1, 0.2 * 0.05)  # 0.05 rad
    assert watch.judge(3.8, at_end=True, matched=False) is None
    watch.commanded(0.0, 0.5, 0.1, 0.2 * 0.05)
    note = watch.judge(3.8, at_end=True, matched=False)
    assert note == (
        "drove 0.00 m and turned 6 deg since the views placed it at the route's end (the route had 0.00 m and "
        "4 deg left)"
    )
