"""`vtr eval --houses`: generated routes taught and repeated in procedural houses (evaluation.house_suite),
with a tiny stand-in model (no accuracy asserted). Development houses only (random:900..999)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from vtr.benchmarks.standin import make_standin_velocitynet
from vtr.evaluation import house_suite
from vtr.evaluation.house_tables import markdown
from vtr.runtime.model_meta import ModelMeta
from vtr.runtime.route_script import parse_route_script
from vtr.sim2d.route_gen import generate_route


@pytest.fixture(scope="module")
def small_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    meta = ModelMeta(image_height=32, image_width=32)
    return make_standin_velocitynet(tmp_path_factory.mktemp("m") / "tiny.onnx", meta=meta, widths=(8, 16, 16))


def test_parse_houses() -> None:
    assert house_suite.parse_houses("900:903") == ("random:900", "random:901", "random:902")
    assert house_suite.parse_houses("905") == ("random:905",)
    assert house_suite.parse_houses("901,random:907,house") == ("random:901", "random:907", "house")
    for bad in ("x", "900:900", "5:2", "-1", "1,1", "1:2:3", "", "random:x", "901,,902"):
        with pytest.raises(ValueError, match="--houses"):
            house_suite.parse_houses(bad)


def test_config_refuses_bad_values(small_model: Path) -> None:
    for kwargs in (
        {"routes_per_house": 0},
        {"noise": 2.0},
        {"seeds": ()},
        {"seeds": (1, 1)},
        {"controller": "nope"},
        {"workers": 0},
    ):
        with pytest.raises(ValueError):
            house_suite.HouseSuiteConfig(houses=("random:900",), model=small_model, **kwargs)


def _run(completed: bool, err: float, cause: str = "") -> dict:
    return {
        "completed": completed,
        "position_error_m": err,
        "max_position_error_m": 2 * err,
        "steps_per_taught_step": 1.5,
        "cause": cause,
        "contacts": 0,
    }


def test_summary_counts_runs_and_averages_errors_over_completed_runs_only() -> None:
    routes = [
        {"house": "random:901", "route_seed": 0, "runs": [_run(True, 0.010), _run(False, 0.5, "stalled: x")]},
        {"house": "random:900", "route_seed": 0, "runs": [_run(True, 0.020), _run(True, 0.030)]},
        {"house": "random:900", "route_seed": 1, "runs": [], "error": "no valid route"},
    ]
    s = house_suite.summarise(routes, ("random:900", "random:901"))
    assert list(s["per_house"]) == ["random:900", "random:901"]
    h900, h901, all_ = s["per_house"]["random:900"], s["per_house"]["random:901"], s["overall"]
    assert (h900["completed"], h900["runs"], h900["routes_not_generated"]) == (2, 2, 1)
    assert h900["mean_error_mm"] == pytest.approx(25.0)
    assert h901["mean_error_mm"] == pytest.approx(10.0) and h901["failure_causes"] == {"stalled": 1}
    assert (all_["completed"], all_["runs"]) == (3, 4) and all_["completion"] == pytest.approx(0.75)
    assert all_["mean_error_mm"] == pytest.approx(20.0) and all_["max_error_mm"] == pytest.approx(60.0)


def test_run_teaches_repeats_and_writes_json_markdown_and_picture(small_model: Path, tmp_path: Path) -> None:
    cfg = house_suite.HouseSuiteConfig(
        houses=("random:900",),
        routes_per_house=1,
        seeds=(0, 1),
        model=small_model,
        workers=1,
        max_steps_factor=1.0,
        oracle=True,
        json_path=tmp_path / "houses.json",
    )
    result = house_suite.run(cfg, progress=False)
    (route,) = result["routes"]
    assert parse_route_script(route["route"]) == generate_route("random:900", 0)
    assert 1 <= route["rooms"] <= 3 and route["subgoals"] == len(route["taught_path"])
    assert [(r["method"], r["seed"]) for r in route["runs"]] == [
        ("velocitynet", 0),
        ("velocitynet", 1),
        ("pose_oracle", 0),
        ("pose_oracle", 1),
    ]
    for run in route["runs"]:
        assert run["ran"] and len(run["path"]) == run["steps"] + 1
        assert run["completed"] == (run["status"] == "finished" and run["contacts"] == 0)
    overall, oracle = result["summary"]["overall"], result["summary"]["pose_oracle"]["overall"]
    assert overall["runs"] == 2 and overall["completed"] == sum(r["completed"] for r in route["runs"][:2])
    assert oracle["runs"] == 2 and oracle["completed"] == sum(r["completed"] for r in route["runs"][2:])
    # the real step's cost over VelocityNet's runs (the oracle's steer is not the runtime's)
    assert result["step_compute"]["runs"] == 2
    assert result["step_compute"]["max"] == max(r["step_compute_ms"]["max"] for r in route["runs"][:2])
    saved = json.loads((tmp_path / "houses.json").read_text())
    assert saved["summary"] == result["summary"]
    md = (tmp_path / "houses.md").read_text()
    assert "| random:900 |" in md and "| **all** |" in md and "Pose oracle" in md and md == markdown(saved)
    assert "Step compute (the runtime's judgement, policy and limits" in md
    assert (tmp_path / "houses.png").stat().st_size > 1000


def test_cli_bad_houses_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from vtr.cli import main

    assert main(["eval", "--houses", "abc"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("vtr eval: --houses 'abc'") and "\n" not in err


def test_an_interrupted_run_keeps_the_finished_routes(
    small_model: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def fake(task: tuple) -> dict:
        house, k, _ = task
        if k == 1:
            raise KeyboardInterrupt
        run = {"method": "velocitynet", **_run(True, 0.01)}
        return {
            "house": house,
            "route_seed": k,
            "rooms": 1,
            "length_m": 2.0,
            "duration_s": 9.0,
            "runs": [run],
        }

    monkeypatch.setattr(house_suite, "evaluate_route", fake)
    cfg = house_suite.HouseSuiteConfig(
        houses=("random:900",),
        routes_per_house=2,
        seeds=(0,),
        model=small_model,
        workers=1,
        json_path=tmp_path / "h.json",
    )
    with pytest.raises(KeyboardInterrupt):
        house_suite.run(cfg, progress=False)
    saved = json.loads((tmp_path / "h.json").read_text())
    assert saved["partial"] == "1 of 2 routes finished" and saved["summary"]["overall"]["completed"] == 1
    assert "Partial result" in (tmp_path / "h.md").read_text()


def test_a_house_that_cannot_be_built_is_reported_not_raised(small_model: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"rooms": []}))  # not a house: sim2d refuses it (HouseError)
    cfg = house_suite.HouseSuiteConfig(houses=(str(bad),), model=small_model, seeds=(0,))
    out = house_suite.evaluate_route((str(bad), 0, cfg))
    assert out["runs"] == [] and out["error"].startswith(f"{bad}: name: missing required field")
