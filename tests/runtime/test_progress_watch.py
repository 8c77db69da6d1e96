"""runtime.progress_watch: images and commanded translation since the last evidence of where the robot is."""

from __future__ import annotations

import pytest

from vtr.runtime.progress_watch import PROGRESS_GAPS, STALL_WINDOWS, ProgressWatch


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


@pytest.mark.parametrize("evidence", ["progress", "match"])
def test_progress_or_a_matching_view_counts_afresh(evidence: str):
    watch = ProgressWatch(100.0)
    watch.judge(3.0, matched=False, window_m=0.5)
    watch.commanded(0.45, 1.0)
    position, matched = (3.0 + PROGRESS_GAPS, False) if evidence == "progress" else (3.0, True)
    assert watch.judge(position, matched=matched, window_m=0.5) is None
    assert watch.travel == 0.0 and watch.since == 0
    watch.commanded(0.45, 1.0)
    assert watch.judge(position, matched=False, window_m=0.5) is None  # 0.45 m of 0.5: not yet


def test_a_small_move_back_and_forth_is_no_progress():
    watch = ProgressWatch(2.0)
    watch.judge(3.0, matched=False, window_m=10.0)
    for i in range(watch.stall_images - 1):
        assert watch.judge(3.0 + (PROGRESS_GAPS / 2) * (i % 2), matched=False, window_m=10.0) is None
    assert watch.judge(3.0, matched=False, window_m=10.0) is not None
