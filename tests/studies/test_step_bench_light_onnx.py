"""The light-matching ONNX probe computes what runtime/light.py does (up to onnxruntime's rounding)."""

from __future__ import annotations

from studies import step_bench_light_onnx


def test_the_onnx_subgraph_matches_the_numpy_light_matching_within_one_level() -> None:
    out = step_bench_light_onnx.run(steps=3, warmup=1, size=32)
    assert out["onnx_nodes"] > 20 and out["numpy_p50_ms"] > 0 and out["onnxruntime_p50_ms"] > 0
    assert out["max_abs_difference"] <= 1 / 255 + 1e-6  # at most one level, where rounding flips
    assert out["values_differing"] <= 0.05 * 3 * 32 * 32
