"""The live status line of `vtr repeat` and the progress line of `vtr eval`/`vtr bench` (runtime/status_line.py):
its text, and that it is written only to a terminal and never in --json mode."""

from __future__ import annotations

import io
import json
import math
import sys

import numpy as np
import pytest
from runtime_fakes import FakeSim, build_velocitynet_onnx, corridor_route

from vtr.runtime.repeat_types import RepeatStatus, StepRecord
from vtr.runtime.route import Route
from vtr.runtime.status_line import (
    LiveLine,
    Progress,
    RepeatStatusLine,
    progress_text,
    repeat_status,
    taught_seconds,
)


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def record(**kw) -> StepRecord:
    base = dict(
        step=3,
        from_subgoal=4,
        subgoal=4,
        action=None,
        events=(),
        error=12.34,
        e_m=17.0,
        v=0.2,
        w=-0.05,
        commanded=True,
        stamp=4.0,
        pose=None,
        latency_ms={},
        image=None,
    )
    return StepRecord(**{**base, **kw})


def test_the_repeat_status_names_subgoal_match_confidence_command_and_time_against_the_teach():
    text = repeat_status(record(), total=10, elapsed_s=4.0, taught_s=8.0, confidence=0.87)
    assert (
        text == "subgoal 5/10  match 12.3  confidence 0.87  v +0.20 m/s  w -0.05 rad/s  4.0 s of 8.0 s taught"
    )
    bare = repeat_status(record(error=math.nan, v=-0.0001), total=10, elapsed_s=1.25)
    assert bare == "subgoal 5/10  v +0.00 m/s  w -0.05 rad/s  1.2 s"  # no match, no localiser, no taught time


def test_a_wait_and_the_end_replace_the_command():
    waiting = record(commanded=False, v=0.0, w=0.0, waited_s=3.2, detail="stop zone; waiting up to 10 s")
    text = repeat_status(waiting, total=10, elapsed_s=7.0, taught_s=8.0, waited_s=3.2, wait_s=10.0)
    assert "waiting: way blocked (3.2 s of 10 s)" in text and "m/s" not in text
    ended = record(commanded=False, status=RepeatStatus.ROBOT_TOO_SLOW, subgoal=11)
    assert repeat_status(ended, total=10, elapsed_s=9.0).startswith(
        "subgoal 10/10  match 12.3  ended: robot_too_slow"
    )


def test_taught_time_from_the_spacing_or_from_poses_and_commands():
    images = np.zeros((5, 8, 8, 3), np.uint8)
    poses = np.array([(0.05 * k, 0.0, 0.0) for k in range(5)])
    commands = np.array([(0.25, 0.0)] * 4 + [(0.0, 0.0)])
    steps = Route(
        images=images, poses=poses, commands=commands, spacing={"rule": "steps", "dt": 0.1, "every": 2}
    )
    assert taught_seconds(steps) == pytest.approx(0.8)
    by_distance = Route(images=images, poses=poses, commands=commands, spacing={"rule": "distance"})
    assert taught_seconds(by_distance) == pytest.approx(4 * 0.05 / 0.25)
    turns = np.array([(0.0, 0.0, 0.5 * k) for k in range(5)])
    spin = Route(images=images, poses=turns, commands=np.array([(0.0, 1.0)] * 5), spacing={"rule": "image"})
    assert taught_seconds(spin) == pytest.approx(2.0)
    unknown = Route(
        images=images, poses=np.full((5, 3), np.nan), commands=commands, spacing={"rule": "image"}
    )
    assert taught_seconds(unknown) is None


def test_the_line_is_written_only_to_a_terminal():
    piped = io.StringIO()
    LiveLine(piped).show("subgoal 1/2", force=True)
    assert piped.getvalue() == ""
    term = Terminal()
    line = LiveLine(term)
    line.show("x" * 500, force=True)
    line.show("too soon")  # within REFRESH_S of the last: skipped
    line.close()
    out = term.getvalue()
    assert out.startswith("\rxxx") and out.endswith("\x1b[K\n") and "too soon" not in out
    assert len(out) < 500  # cut to the terminal's width: a wrapped line cannot be overwritten
    assert LiveLine(Terminal(), enabled=False).enabled is False
    gone = Terminal()
    gone.close()  # the terminal went away: the line falls silent instead of ending the run
    closed = LiveLine(gone)
    closed.show("subgoal 1/2", force=True)
    closed.close()
    assert closed.enabled is False
    shut = io.StringIO()
    shut.close()
    assert LiveLine(shut).enabled is False and LiveLine(object()).enabled is False  # type: ignore[arg-type]


def test_the_repeat_line_follows_the_robot_clock_and_always_shows_the_end():
    term = Terminal()
    status = RepeatStatusLine(10, taught_s=8.0, wait_s=10.0, confidence=lambda: 0.5, line=LiveLine(term))
    status(record(stamp=1.0))
    status(record(stamp=3.5, commanded=False, status=RepeatStatus.FINISHED))
    status.close()
    out = term.getvalue()
    assert "\rsubgoal 5/10  match 12.3  confidence 0.50  v +0.20" in out
    assert "ended: finished  2.5 s of 8.0 s taught" in out and out.endswith("\n")


def test_progress_text_and_its_line():
    assert progress_text("vtr eval", 0, 4, 0.0) == "vtr eval: 0/4 (0%), 0.0 s"
    assert progress_text("vtr eval", 1, 4, 10.0, "square") == (
        "vtr eval: 1/4 (25%), 10.0 s, about 30.0 s left: square"
    )
    assert progress_text("vtr bench latency", 2, None, 3.0) == "vtr bench latency: 2 done, 3.0 s"
    assert progress_text("vtr bench latency", 1, 6, 3.0, "stages", eta=False) == (
        "vtr bench latency: 1/6 (17%), 3.0 s: stages"
    )
    term = Terminal()
    with Progress("vtr eval", 2, stream=term) as progress:
        progress.advance("a")
        progress.advance("b")
    assert "vtr eval: 2/2 (100%)" in term.getvalue() and term.getvalue().endswith("\n")
    quiet = Terminal()
    Progress("vtr eval", 2, quiet=True, stream=quiet).advance("a")
    assert quiet.getvalue() == ""


def test_a_log_gets_plain_progress_lines_only_from_a_long_job():
    log = io.StringIO()  # not a terminal: a nohup log
    with Progress("vtr eval", 3, stream=log, log_every_s=0.0) as progress:
        progress.advance("a")
        progress.start("b")
        progress.advance("b")
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue() and "\x1b" not in log.getvalue()
    assert lines[0].startswith("vtr eval: 1/3 (33%)") and lines[-1].startswith("vtr eval: 2/3 (67%)")
    short = io.StringIO()  # a job shorter than the interval writes nothing
    with Progress("vtr eval", 2, stream=short) as progress:
        progress.advance("a")
        progress.advance("b")
    assert short.getvalue() == ""


@pytest.fixture(scope="module")
def policy_path(tmp_path_factory):
    return build_velocitynet_onnx(str(tmp_path_factory.mktemp("model") / "tiny.onnx"))


@pytest.mark.parametrize("json_mode", [False, True])
def test_vtr_repeat_shows_the_line_on_a_terminal_and_never_with_json(
    policy_path, tmp_path, monkeypatch, capsys, json_mode
):
    from vtr.cli import main
    from vtr.sim2d.server import ServerThread

    route = tmp_path / "route.npz"
    corridor_route().save(route)
    term = Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    with ServerThread(FakeSim()) as server:
        argv = ["repeat", "--sim", server.endpoint, "--model", policy_path, "--route", str(route)]
        assert main([*argv, "--profile", "paper", *(["--json"] if json_mode else [])]) == 0
    out, err = capsys.readouterr().out, term.getvalue()
    if json_mode:
        assert json.loads(out)["completed"] and "\r" not in err
    else:
        assert "\rsubgoal " in err and "ended: finished" in err and err.endswith("\n")
        assert out.startswith("vtr repeat: finished")


def test_vtr_repeat_is_quiet_when_stderr_is_not_a_terminal(policy_path, tmp_path, capsys):
    from vtr.cli import main
    from vtr.sim2d.server import ServerThread

    route = tmp_path / "route.npz"
    corridor_route().save(route)
    with ServerThread(FakeSim()) as server:
        argv = ["repeat", "--sim", server.endpoint, "--model", policy_path, "--route", str(route)]
        assert main([*argv, "--profile", "paper"]) == 0
    assert "subgoal" not in capsys.readouterr().err


def test_a_wait_for_a_blocked_way_counts_up_on_the_record_and_the_line():
    from test_follower import WithScan, _run

    rep, records = _run(WithScan(box_x=0.55), wait_s=2.0)
    waits = [r.waited_s for r in records if r.waited_s is not None]
    assert rep.status is RepeatStatus.BLOCKED and len(waits) >= 20
    assert waits == sorted(waits) and waits[0] == 0.0 and 1.5 < waits[-1] < 2.0
    assert all(r.waited_s is None for r in records if r.commanded)
    text = repeat_status(records[-2], 9, 3.0, waited_s=records[-2].waited_s, wait_s=2.0)
    assert f"waiting: way blocked ({waits[-1]:.1f} s of 2 s)" in text


def test_progress_yields_futures_as_they_finish_and_moves_its_clock_meanwhile():
    import time
    from concurrent.futures import ThreadPoolExecutor

    term = Terminal()
    with ThreadPoolExecutor(2) as ex, Progress("vtr eval", 2, stream=term) as progress:
        futures = [ex.submit(time.sleep, 0.5), ex.submit(lambda: 7)]
        finished = [f.result() for f in progress.as_completed(futures, every_s=0.1)]
    assert sorted(finished, key=str) == [7, None]
    assert term.getvalue().count("vtr eval: 0/2") + term.getvalue().count("vtr eval: 1/2") >= 3  # ticks
