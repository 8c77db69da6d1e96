"""`vtr eval --run RUN.mcap --taught ROUTE.npz` scores a run recorded by `vtr repeat --mcap`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from vtr import cli
from vtr.runtime.mcap_log import McapRunWriter
from vtr.runtime.route import Route


def taught(tmp_path: Path) -> Path:
    poses = np.array([(0.05 * k, 0.0, 0.0) for k in range(5)])
    route = Route(
        images=np.zeros((5, 8, 8, 3), np.uint8), poses=poses, commands=np.zeros((5, 2)), name="line"
    )
    route.save(tmp_path / "route.npz")
    return tmp_path / "route.npz"


def recorded(tmp_path: Path, offset_y: float, with_poses: bool = True) -> Path:
    with McapRunWriter(tmp_path / "run.mcap") as writer:
        for k in range(9):
            pose = (0.025 * k, offset_y, 0.0) if with_poses else None
            writer.record(
                {"stamp": 0.1 * k, "v": 0.25, "w": 0.0, "pose": pose, "error": 5.0, "subgoal": k // 2}
            )
        writer.record_summary({"status": "finished", "subgoals_reached": 5, "steps": 9})
    return tmp_path / "run.mcap"


def test_eval_scores_a_recorded_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run, route = recorded(tmp_path, offset_y=0.01), taught(tmp_path)
    assert (
        cli.main(["eval", "--run", str(run), "--taught", str(route), "--json", str(tmp_path / "s.json")]) == 0
    )
    result = json.loads(capsys.readouterr().out)
    assert result["status"] == "finished" and result["subgoals_reached"] == 5 and result["steps"] == 9
    assert result["position_error_m"]["mean"] == pytest.approx(0.01, abs=1e-9)
    assert json.loads((tmp_path / "s.json").read_text()) == result


def test_eval_says_why_a_run_without_poses_cannot_be_scored(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run, route = recorded(tmp_path, 0.0, with_poses=False), taught(tmp_path)
    assert cli.main(["eval", "--run", str(run), "--taught", str(route)]) == 2
    assert "the run has no poses" in capsys.readouterr().err
    assert cli.main(["eval", "--run", str(run)]) == 2
    assert "--run needs --taught" in capsys.readouterr().err


def _png(path: Path) -> bool:
    return path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plots_of_a_recorded_run_show_path_error_and_commands(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run, route, plots = recorded(tmp_path, offset_y=0.01), taught(tmp_path), tmp_path / "plots"
    assert cli.main(["eval", "--run", str(run), "--taught", str(route), "--plots", str(plots)]) == 0
    out, err = capsys.readouterr()
    names = ["run_path.png", "run_error.png", "run_commands.png"]
    assert all(_png(plots / name) for name in names)
    result = json.loads(out)  # stdout stays the JSON; the files are named on stderr and in it
    assert result["plots"] == [str(plots / name) for name in names]
    assert all(f"wrote {plots / name}" in err for name in names) and "not in the run" not in err


def test_plots_of_a_run_without_poses_draw_what_exists_and_say_what_is_missing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run, route, plots = recorded(tmp_path, 0.0, with_poses=False), taught(tmp_path), tmp_path / "plots"
    assert cli.main(["eval", "--run", str(run), "--taught", str(route), "--plots", str(plots)]) == 0
    err = capsys.readouterr().err
    assert _png(plots / "run_error.png") and _png(plots / "run_commands.png")
    assert _png(plots / "run_path.png")  # the taught path alone
    missing = [line for line in err.splitlines() if "not in the run" in line]
    assert len(missing) == 1 and "the run's poses (the robot reported none)" in missing[0]


def test_plots_into_a_file_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run, route = recorded(tmp_path, 0.0), taught(tmp_path)
    (tmp_path / "taken").write_text("a file")
    assert (
        cli.main(["eval", "--run", str(run), "--taught", str(route), "--plots", str(tmp_path / "taken")]) == 2
    )
    err = capsys.readouterr().err
    assert err.startswith("vtr eval: --plots") and len(err.strip().splitlines()) == 1
