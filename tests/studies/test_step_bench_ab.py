"""The step A/B script (studies/step_bench_ab.py) on a tiny stand-in model (no timing assertions)."""

from __future__ import annotations

from studies import step_bench_ab


def test_the_ab_script_steps_all_three_variants_on_a_saved_route(tiny: tuple[str, str]) -> None:
    model, route = tiny
    out = step_bench_ab.medians(route, model, steps=3, warmup=1)
    assert set(out) == {"raw", "patch", "light"} and all(v > 0 for v in out.values())
    inside = step_bench_ab.sections(route, model, steps=3, warmup=1, variant="light")
    assert {
        "step",
        "controller.judge",
        "matcher.features",
        "policy.match",
        "onnx._run",
        "robot.stop",
    } <= set(inside)
    assert inside["step"] > inside["onnx._run"] > 0


def test_the_ab_script_splits_each_step_into_compute_and_link(tiny: tuple[str, str]) -> None:
    model, route = tiny
    out = step_bench_ab.split(route, model, steps=3, warmup=1)
    assert set(out) == {"inference"} | {
        f"{v}.{part}"
        for v in ("raw", "patch", "light")
        for part in ("step", "compute", "link", "compute_cpu")
    }
    assert all(0 < v["p50_us"] <= v["p99_us"] for v in out.values())
    assert out["light.compute"]["p50_us"] < out["light.step"]["p99_us"]
