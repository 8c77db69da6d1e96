"""`vtr eval --suite pace` (evaluation/realtime_pace.py): a route taught on a lockstep simulator, repeated on a realtime
one by `vtr repeat`'s code, its wall time set against the taught time."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from vtr.evaluation import realtime_pace


def _script(folder: Path) -> Path:
    folder.mkdir()
    path = folder / "straight.json"
    start = {"x": 7.975, "y": 5.525, "yaw": 1.85459}  # a free stretch of the paper-style house
    path.write_text(
        json.dumps({"name": "straight", "start": start, "segments": [{"v": 0.2, "w": 0.0, "duration": 1.5}]})
    )
    return path


def test_a_realtime_repeat_is_timed_against_the_teach(tmp_path: Path) -> None:
    script = _script(tmp_path / "routes")
    rows = realtime_pace.pace([script], [0], [None, "continuous"], realtime_pace.DEFAULT_MODEL, 0.0, tmp_path)
    assert [r["motion"] for r in rows] == ["default", "continuous"]
    for row in rows:
        assert row["status"] == "finished", row
        assert row["taught_s"] == pytest.approx(1.5, abs=0.11)  # the 1.5 s segment, to a subgoal step
        assert row["time_ratio"] == pytest.approx(row["wall_s"] / row["taught_s"], rel=0.01)
        # no upper bound: a wall clock on a shared machine waits for a core (6x under load 6); the pace itself
        # is a benchmark (`vtr eval --suite pace`), not a timed test
        assert row["time_ratio"] > 0.5 and row["mean_error_mm"] < 30 and row["off_route"] == ""
    table = realtime_pace.table(rows)
    assert "| default | 1 | 1 | 1 |" in table and "| continuous | 1 | 1 | 1 |" in table


def _row(status: str, off_route: str = "", ratio: float = 1.05) -> dict:
    return {
        "motion": "default", "status": status, "off_route": off_route, "time_ratio": ratio, "steps_ratio": 1.0,
        "mean_error_mm": 8.0,
    }  # fmt: skip


def test_a_run_that_finished_off_the_route_is_counted_apart() -> None:
    rows = [_row("finished"), _row("finished", "final position 54 mm > 50 from the end", 1.2), _row("lost")]
    line = realtime_pace.table(rows).splitlines()[-1]
    assert line.startswith("| default | 3 | 2 | 1 | 1.125 / 1.2 |")


def test_the_report_is_written_beside_the_json(tmp_path: Path) -> None:
    rows = [_row("finished")]
    md = realtime_pace.write_outputs(tmp_path / "pace.json", rows, "TABLE\nload average 0.1")
    assert md == tmp_path / "pace.md" and md.read_text() == "TABLE\nload average 0.1\n"
    assert json.loads((tmp_path / "pace.json").read_text()) == rows


def test_a_folder_without_routes_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from vtr.cli import main

    assert main(["eval", "--suite", "pace", "--routes", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("vtr eval: no ROUTE.json files") and "\n" not in err
