"""`vtr eval --quick` and `vtr demo` on a short route with a tiny stand-in model (no accuracy asserted)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from vtr.benchmarks.standin import make_standin_velocitynet
from vtr.runtime.model_meta import ModelMeta

SHORT_ROUTE = {
    "name": "short",
    "segments": [{"v": 0.2, "w": 0.0, "duration": 0.8}, {"v": 0.1, "w": 0.5, "duration": 0.6}],
}


@pytest.fixture(scope="module")
def small_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    meta = ModelMeta(image_height=32, image_width=32)
    return make_standin_velocitynet(tmp_path_factory.mktemp("m") / "tiny.onnx", meta=meta, widths=(8, 16, 16))


@pytest.fixture(scope="module")
def short_route(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from vtr.sim2d import Simulator

    start = Simulator().house.start_poses[0]
    data = dict(SHORT_ROUTE, start={"x": float(start.x), "y": float(start.y), "yaw": float(start.yaw)})
    path = tmp_path_factory.mktemp("r") / "short.json"
    path.write_text(json.dumps(data))
    return path


def test_eval_quick_writes_every_output(small_model: Path, short_route: Path, tmp_path: Path) -> None:
    from vtr.evaluation import harness as evaluate

    cfg = evaluate.EvalConfig(
        model=small_model,
        routes=(str(short_route),),
        quick=True,
        workers=1,
        json_path=tmp_path / "eval.json",
        plots_dir=tmp_path / "plots",
    )
    result = evaluate.run(cfg)
    (route,) = result["routes"]
    assert route["name"] == "short" and route["subgoals"] >= 2
    runs = route["scenarios"]["noise"]
    assert set(runs) == {"velocitynet", "open_loop"}
    for run in runs.values():
        assert run["position_error_m"]["n"] == route["subgoals"]
        assert 0.0 <= run["completion"] <= 1.0
        assert math.isfinite(run["mean_cross_track_error_m"])
        assert len(run["repeated_poses"]) == run["steps"] + 1
    # open loop replays every taught control step
    assert runs["open_loop"]["steps"] == round(0.8 / 0.1) + round(0.6 / 0.1)
    assert runs["velocitynet"]["policy_ms"]["p50"] > 0
    on_disk = json.loads((tmp_path / "eval.json").read_text())
    assert on_disk["routes"][0]["scenarios"]["noise"]["open_loop"]["steps"] == runs["open_loop"]["steps"]
    md = (tmp_path / "eval.md").read_text()
    assert "| short | velocitynet |" in md and "Bar (issue 5)" in md
    pngs = sorted(p.name for p in (tmp_path / "plots").glob("*.png"))
    assert pngs == ["short_error.png", "short_path.png"]
    from vtr.evaluation import report

    section = report.build(None, [on_disk])
    assert "### Closed-loop tracking" in section and f"--routes {short_route}" in section


def test_open_loop_drifts_under_noise_and_not_without(short_route: Path) -> None:
    from vtr.evaluation import harness as evaluate
    from vtr.evaluation import runs
    from vtr.runtime.route_script import load_route_script

    route, script = evaluate.teach(short_route, (32, 32), 0.1)
    clean = runs.repeat_open_loop(evaluate.make_robot(0.0, (32, 32)), script, tuple(route.poses[0]), 0, 0.1)
    np.testing.assert_allclose(np.asarray(clean.poses)[-1], route.poses[-1], atol=1e-6)
    noisy = runs.repeat_open_loop(evaluate.make_robot(0.3, (32, 32)), script, tuple(route.poses[0]), 0, 0.1)
    assert np.abs(np.asarray(noisy.poses)[-1] - route.poses[-1]).max() > 1e-4
    assert load_route_script(short_route).name == "short"


def test_demo_runs_end_to_end(small_model: Path, short_route: Path, tmp_path: Path) -> None:
    from vtr.evaluation import demo

    result = demo.run(demo.DemoConfig(model=small_model, route=str(short_route), out=tmp_path))
    assert [p.name for p in tmp_path.iterdir()] == ["short.png"]  # the picture only, not the taught route
    assert Path(result["png"]) == tmp_path / "short.png"
    assert len(result["open_loop_poses"]) == round(0.8 / 0.1) + round(0.6 / 0.1) + 1
    assert result["summary"]["subgoals_total"] >= 2
    assert result["velocitynet"]["position_error_m"]["n"] == result["summary"]["subgoals_total"]


def test_pose_oracle_closes_the_loop(small_model: Path, short_route: Path) -> None:
    # The harness end to end (daemon, controller, pose recording, scoring) with a policy that can succeed.
    from vtr.evaluation import harness as evaluate

    cfg = evaluate.EvalConfig(
        model=small_model, routes=(str(short_route),), quick=True, workers=1, oracle=True, open_loop=False
    )
    run = evaluate.run(cfg)["routes"][0]["scenarios"]["noise"]["pose_oracle"]
    assert run["completed"] and run["outcome"] == "finished"
    assert run["position_error_m"]["mean"] < 0.02
    assert sorted(run["switch_poses"]["index"]) == list(range(run["subgoals"]))


def test_vtr_eval_quick_cli(small_model: Path, short_route: Path, tmp_path: Path) -> None:
    from vtr.cli import main

    out = tmp_path / "e.json"
    assert (
        main(
            ["eval", "--model", str(small_model), "--quick", "--routes", str(short_route), "--json", str(out)]
        )
        == 0
    )
    assert json.loads(out.read_text())["routes"][0]["name"] == "short"
    assert main(["eval", "--model", str(small_model), "--noise", "2"]) == 2


def test_demo_exit_code_says_whether_the_repeat_finished(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from vtr.cli import main
    from vtr.evaluation import demo

    for completed, code in ((True, 0), (False, 1)):
        monkeypatch.setattr(demo, "run", lambda cfg, c=completed: {"summary": {"completed": c}})
        assert main(["demo", "--out", str(tmp_path / "d")]) == code
