"""Latency harness smoke run on a tiny ONNX (few iterations; no timing assertions)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from vtr.benchmarks import latency, latency_report
from vtr.benchmarks.backends import velocitynet_like
from vtr.benchmarks.flops import count_flops
from vtr.benchmarks.standin import make_standin_velocitynet
from vtr.runtime.model_meta import ModelMeta

TINY = ModelMeta(image_height=32, image_width=32, horizon=2)


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_standin_velocitynet(tmp_path_factory.mktemp("m") / "tiny.onnx", meta=TINY, widths=(4, 8))


def test_flop_count_matches_hand_count(tiny_model: Path) -> None:
    # conv0: 6->4, 3x3, stride 2 on 32x32 -> 16x16x4 outputs * 54 MACs; conv1: 4->8 -> 8x8x8 * 36;
    # head: 1x1 conv 8 -> 4 on 1x1 -> 4 * 8
    macs = 16 * 16 * 4 * 54 + 8 * 8 * 8 * 36 + 4 * 8
    out = count_flops(tiny_model)
    assert out["macs_by_op"] == {"Conv": macs}
    assert out["gflop"] == pytest.approx(2 * macs / 1e9)


def test_torch_eager_is_the_real_velocitynet_with_the_models_widths(tmp_path: Path) -> None:
    from vtr.export.onnx_export import export_onnx, velocitynet_meta
    from vtr.training.config import VelocityNetConfig
    from vtr.training.models import VelocityNet

    cfg = VelocityNetConfig(image_size=32, channels=(4, 4, 8, 8, 8, 8, 8), horizon=3)
    path = tmp_path / "v.onnx"
    export_onnx(VelocityNet(cfg), path, velocitynet_meta(cfg))
    net = velocitynet_like(path)
    assert type(net) is VelocityNet and net.cfg.channels == cfg.channels and net.cfg.horizon == 3
    assert net.cfg.image_size == 32 and not net.training


def test_torch_eager_refuses_a_graph_that_is_not_velocitynet(tiny_model: Path) -> None:
    with pytest.raises(ValueError, match="8 convolutions"):
        velocitynet_like(tiny_model)


def test_latency_smoke_run(tiny_model: Path, tmp_path: Path) -> None:
    cfg = latency.LatencyConfig(
        model=tiny_model,
        thread_counts=(1,),
        steps=3,
        warmup=1,
        matmul_size=32,
        zmq=False,
        sim_steps=0,
        json_path=tmp_path / "lat.json",
    )
    result = latency.run(cfg)
    stages = result["stages"]["stages"]
    names = (
        "frame_decode",
        "preprocess",
        "inference",
        "image_error",
        "light_matching",
        "whole_step_raw",
        "whole_step",
        "whole_step_continuous",
        "whole_step_match_light",
    )
    for name in names:
        assert stages[name]["n"] == 3 and stages[name]["p99_ms"] >= stages[name]["p50_ms"] > 0
    b = result["backends"]["threads"]["1"]["backends"]
    assert b["ort_fp32"]["gflop_per_step"] == pytest.approx(result["gflop"])
    assert "skipped" in b["ort_int8"]  # no int8 twin beside the tiny model
    assert result["memory"]["heavy_modules_loaded"] == []
    assert result["memory"]["peak_rss_mb"] > 0
    assert all(result["ratios"][key] is not None for key in latency_report.STEP_VARIANTS)
    # the route's views differ, so the whole step times patch matching, not the plain-route fallback
    assert result["stages"]["matching"] == {
        "whole_step_raw": "raw",
        "whole_step": "patch",
        "whole_step_continuous": "patch",
        "whole_step_match_light": "patch",
        "whole_step_taught": "patch",
        "whole_step_end": "patch",
    }
    # the step on the route with its taught poses, and in its end zone, are judged by the same budget
    taught = result["stages"]["compute"][latency_report.TAUGHT_VARIANT]["step_compute"]
    assert result["ratios"]["taught_step_compute_p99_ms"] == taught["p99_ms"]
    assert result["ratios"]["meets_target"]["taught_step_compute_p99_ms"] is (taught["p99_ms"] <= 1.0)
    end = result["stages"]["compute"][latency_report.END_VARIANT]["step_compute"]
    assert result["ratios"]["end_step_compute_p99_ms"] == end["p99_ms"]
    assert result["ratios"]["meets_target"]["end_step_compute_p99_ms"] is (end["p99_ms"] <= 1.0)
    assert "in its end zone" in latency_report.format_report(result)
    assert "no target" not in latency_report.format_report(result)
    on_disk = json.loads((tmp_path / "lat.json").read_text())
    assert on_disk["gflop"] == pytest.approx(result["gflop"])
    # each whole step's compute apart from its link, and the budget judged on vtr repeat's default step
    for name, c in result["stages"]["compute"].items():
        assert (
            c["step_compute"]["n"] == c["link"]["n"] == c["step_compute_cpu"]["n"] == c["inference"]["n"] == 3
        )
        assert 0 < c["step_compute_cpu"]["p50_ms"]
        assert 0 < c["step_compute"]["p50_ms"] < stages[name]["p99_ms"] and c["link"]["p50_ms"] > 0
    default = result["stages"]["compute"][latency_report.DEFAULT_VARIANT]["step_compute"]
    assert result["ratios"]["step_compute_p99_ms"] == default["p99_ms"]
    assert result["ratios"]["meets_target"]["step_compute_p99_ms"] is (default["p99_ms"] <= 1.0)
    report_text = latency_report.format_report(result)
    assert "targets (issues 5, 11 and 19)" in report_text and "step compute (Repeater.step" in report_text
    from vtr.evaluation import report

    md = report.build(on_disk, [])
    assert "| whole_step |" in md and "| 1 | ort_fp32 |" in md and "peak RSS" in md


def test_config_rejects_bad_values(tiny_model: Path) -> None:
    with pytest.raises(ValueError, match="threads"):
        latency.LatencyConfig(model=tiny_model, threads=0)
    with pytest.raises(ValueError, match="nope"):
        latency.LatencyConfig(model=tiny_model, backends=("nope",))
    with pytest.raises(FileNotFoundError, match="not found"):
        latency.LatencyConfig(model=tiny_model.with_name("missing.onnx"))


def test_vtr_bench_latency_cli(tiny_model: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from vtr.cli import main

    quick = "--steps 3 --warmup 1 --thread-counts 1 --backends ort_fp32 --matmul-size 32 --no-zmq --no-memory"
    argv = ["bench", "latency", "--model", str(tiny_model), *quick.split(), "--sim-steps", "0"]
    argv += ["--json", str(tmp_path / "l.json"), "--also-models", str(tiny_model)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "whole_step" in out and f"{tiny_model} (" in out and "same run" in out
    written = json.loads((tmp_path / "l.json").read_text())
    assert written["stages"]["stages"]["whole_step"]["n"] == 3
    other = written["also_models"][str(tiny_model)]  # the other network's step and inference, paired
    assert set(other["step_overhead"]) == set(latency_report.STEP_VARIANTS)
    assert other["stages"]["pairs"]["whole_step_match_light"]["inference"]["n"] == 3
    assert main(["bench", "latency", "--model", str(tmp_path / "missing.onnx")]) == 2


def test_the_taught_step_judges_the_floor_as_a_real_routes_does(tmp_path: Path) -> None:
    """On the sample route with its taught poses and forward commands the obstruction detector scores the
    floor ahead and the side estimate registers the floor rows; with all poses zero neither has floor."""
    from vtr.benchmarks.step_bench import BenchStep, sample_taught

    meta = ModelMeta(image_height=128, image_width=128, horizon=2)
    model = make_standin_velocitynet(tmp_path / "m.onnx", meta=meta, widths=(4, 8))
    current, route, poses = sample_taught(128, 128)
    seen: dict[str, list[int]] = {}
    for name, step in (
        ("taught", BenchStep(model, 1, current, route, match_light=True, poses=poses)),
        ("plain", BenchStep(model, 1, current, route, match_light=True)),
    ):
        ctl = step.repeater.controller
        calls = seen[name] = []
        estimate = ctl.side.estimate if ctl.side is not None else None
        if estimate is not None:
            ctl.side.estimate = lambda *a, calls=calls, estimate=estimate: calls.append(1) or estimate(*a)
        for _ in range(4):
            step()
        regions = ctl.obstruction.weights if ctl.obstruction is not None else None
        seen[name + "_region"] = [int(regions is not None and regions.any())]
    assert seen["taught"] and seen["taught_region"] == [1]
    assert not seen["plain"] and seen["plain_region"] == [0]


def test_the_taught_step_goes_on_for_as_many_steps_as_the_bench_times(tmp_path: Path) -> None:
    """The bench's view never moves while every step drives on: the follower's no-progress watch ends such a
    repeat after its window's taught travel (a robot should stop there), which ended `vtr bench latency`
    with an error; the bench counts the watch afresh each call and the repeat goes on."""
    from vtr.benchmarks.step_bench import BenchStep, sample_taught

    meta = ModelMeta(image_height=128, image_width=128, horizon=2)
    model = make_standin_velocitynet(tmp_path / "m.onnx", meta=meta, widths=(4, 8))
    current, route, poses = sample_taught(128, 128)
    step = BenchStep(model, 1, current, route, match_light=True, poses=poses)
    for _ in range(150):
        assert step().commanded
    assert len(step.compute_ms) == 150


def test_the_end_step_registers_the_floor_along_the_route_on_every_call(tmp_path: Path) -> None:
    """The end variant holds the belief in the route's end zone, where the floor arrival registers the taught
    floor along the route on every step (the costliest judgement of a real route); mid-route it never does."""
    from vtr.benchmarks.step_bench import BenchStep, sample_end_view, sample_taught

    meta = ModelMeta(image_height=128, image_width=128, horizon=2)
    model = make_standin_velocitynet(tmp_path / "m.onnx", meta=meta, widths=(4, 8))
    current, route, poses = sample_taught(128, 128)
    end_view = sample_end_view(128, 128, poses, route)
    counts = {}
    for name, step in (
        (
            "end",
            BenchStep(model, 1, end_view, route, match_light=True, poses=poses, hold_at=len(route) - 1.5),
        ),
        ("taught", BenchStep(model, 1, current, route, match_light=True, poses=poses)),
    ):
        arrival = step.repeater.controller.arrival
        assert arrival is not None
        calls = counts[name] = []
        along = arrival.registration.along
        arrival.registration.along = lambda *a, calls=calls, along=along, **k: (
            calls.append(1) or along(*a, **k)
        )
        for _ in range(20):
            assert step().commanded  # the view half a step short: not arrived, every step commands
    assert len(counts["end"]) == 20 and not counts["taught"]
