"""The summary of a `vtr bench latency` result (benchmarks.latency): the targets of issues 5, 11 and 19, and
the text report it prints. Issue 19 retired the ratio target (whole step within 15% of inference) for an
absolute budget: p99 step compute <= 1 ms at 1 thread, the link's round trip reported apart; the ratios are
still reported."""

from __future__ import annotations

from typing import Any

#: Targets from issues 5, 11 and 19 (name -> (description, comparison, threshold)).
TARGETS = {
    "ort_fp32_vs_torch_eager": ("torch eager p50 / onnxruntime fp32 p50", ">=", 3.0),
    "int8_vs_fp32": ("onnxruntime fp32 p50 / int8 p50", ">=", 2.5),
    "step_compute_p99_ms": ("p99 step compute (ms), vtr repeat's default step", "<=", 1.0),
    "taught_step_compute_p99_ms": ("same, on a route with taught poses (detector, side)", "<=", 1.0),
    "end_step_compute_p99_ms": ("same, in its end zone (+ the floor along the route)", "<=", 1.0),
    "fp32_vs_matmul": ("fp32 achieved GFLOP/s / matmul GFLOP/s", ">=", 0.60),
}
#: The whole-step variant `vtr repeat` runs by default (the route localiser, patch matching, light matching).
DEFAULT_VARIANT = "whole_step_match_light"
#: The same step on a route with taught poses and forward commands: the obstruction detector and the side
#: estimate do on it what they do on every forward step of a real route (on DEFAULT_VARIANT's route, whose
#: poses are all zero, neither has floor to judge). A real route's step: judged by the same 1 ms budget.
TAUGHT_VARIANT = "whole_step_taught"
#: The same step in the route's end zone (the taught route's last view, the belief held there): the floor
#: arrival registers the floor along the route as well, at every step of a real route's last gaps. Judged too.
END_VARIANT = "whole_step_end"
#: What each retired step_overhead ratio described (still reported, no longer a target).
OVERHEADS = {
    "step_overhead_raw": "whole step p50 / inference p50 - 1, raw error",
    "step_overhead": "same, patch matching (the controller's default)",
    "step_overhead_continuous": "same, no zero command between steps",
    "step_overhead_match_light": "same, + light matching (vtr repeat's default)",
}
#: The whole-step variant behind each step_overhead ratio.
STEP_VARIANTS = {
    "step_overhead_raw": "whole_step_raw",
    "step_overhead": "whole_step",
    "step_overhead_continuous": "whole_step_continuous",
    "step_overhead_match_light": "whole_step_match_light",
}


def ratios(result: dict[str, Any]) -> dict[str, Any]:
    """The issue's target ratios from a result dict (None where an input is missing)."""
    one = result["backends"]["threads"].get("1") or next(iter(result["backends"]["threads"].values()))
    b = one["backends"]

    def p50(name: str) -> float | None:
        return b.get(name, {}).get("p50_ms")

    out: dict[str, Any] = {}
    fp32, torch_eager, int8 = p50("ort_fp32"), p50("torch_eager"), p50("ort_int8")
    out["ort_fp32_vs_torch_eager"] = torch_eager / fp32 if fp32 and torch_eager else None
    out["int8_vs_fp32"] = fp32 / int8 if fp32 and int8 else None
    st = result["stages"]["stages"]
    pairs = result["stages"].get("pairs", {})  # results written before the paired timing: the stage loop's
    for key, variant in STEP_VARIANTS.items():
        whole = st.get(variant)
        inference = pairs.get(variant, {}).get("inference", st["inference"])
        out[key] = whole["p50_ms"] / inference["p50_ms"] - 1.0 if whole else None
    compute = result["stages"].get("compute", {}).get(DEFAULT_VARIANT)  # results before issue 19: none
    out["step_compute_p99_ms"] = compute["step_compute"]["p99_ms"] if compute else None
    taught = result["stages"].get("compute", {}).get(TAUGHT_VARIANT)  # results before session 4: none
    out["taught_step_compute_p99_ms"] = taught["step_compute"]["p99_ms"] if taught else None
    end = result["stages"].get("compute", {}).get(END_VARIANT)  # results before session 18: none
    out["end_step_compute_p99_ms"] = end["step_compute"]["p99_ms"] if end else None
    out["fp32_vs_matmul"] = b.get("ort_fp32", {}).get("fraction_of_matmul")
    verdict = {}
    for key, (_, op, threshold) in TARGETS.items():  # the retired step_overhead ratios have none
        value = out[key]
        verdict[key] = None if value is None else (value >= threshold if op == ">=" else value <= threshold)
    out["meets_target"] = verdict
    return out


def format_report(result: dict[str, Any]) -> str:
    lines = [f"model: {result['model']}  ({result['gflop']:.3f} GFLOP per step, 1 MAC = 2 FLOP)"]
    lines.append(f"machine: {result['machine']['cores']} cores, {result['machine']['processor']}")
    st = result["stages"]
    lines += ["", f"runtime stages at {st['threads']} thread(s)  [codec: {st['codec']}; step: {st['step']}]"]
    lines.append(f"  {'stage':<24}{'p50 ms':>10}{'p99 ms':>10}")
    pairs = st.get("pairs", {})
    for name, t in st["stages"].items():
        paired = f"   inference {pairs[name]['inference']['p50_ms']:.3f} in its loop" if name in pairs else ""
        lines.append(f"  {name:<24}{t['p50_ms']:>10.3f}{t['p99_ms']:>10.3f}{paired}")
    if "matching" in st:
        lines.append(
            "  image comparison in force: " + ", ".join(f"{k} {v}" for k, v in st["matching"].items())
        )
    lines += _compute_lines(st.get("compute", {}))
    z = result["zmq"]
    if "skipped" in z:
        lines.append(f"  {'zmq_round_trip':<16}   skipped: {z['skipped']}")
    else:
        for name, t in z["calls"].items():
            label = "zmq " + name if name != "render_in_process" else "(sim render)"
            lines.append(f"  {label:<16}{t['p50_ms']:>10.3f}{t['p99_ms']:>10.3f}")
        lines.append(f"  {'zmq transport':<16}{z['transport_p50_ms']:>10.3f}  (observe round trip - render)")
    for threads, entry in result["backends"]["threads"].items():
        mm = entry["matmul"]
        np_rate = "n/a" if mm["numpy_gflops"] is None else f"{mm['numpy_gflops']:.1f}"
        lines += [
            "",
            f"backends at {threads} thread(s); float32 matmul {mm['n']}^3: onnxruntime {mm['ort_gflops']:.1f}, "
            f"numpy {np_rate} GFLOP/s",
            f"  {'backend':<12}{'p50 ms':>10}{'p99 ms':>10}{'GFLOP/s':>10}{'of matmul':>11}",
        ]
        for name, b in entry["backends"].items():
            if "skipped" in b:
                lines.append(f"  {name:<12}   skipped: {b['skipped'][:90]}")
            else:
                lines.append(
                    f"  {name:<12}{b['p50_ms']:>10.3f}{b['p99_ms']:>10.3f}{b['achieved_gflops']:>10.2f}"
                    f"{b['fraction_of_matmul']:>10.0%}"
                )
    mem = result["memory"]
    lines.append("")
    if "skipped" in mem:
        lines.append(f"runtime-only process peak RSS: skipped ({mem['skipped']})")
    elif mem:
        lines.append(
            f"runtime-only process peak RSS: {mem['peak_rss_mb']:.1f} MB over {mem['steps']} steps "
            f"(heavy modules loaded: {', '.join(mem['heavy_modules_loaded']) or 'none'})"
        )
    sim = result.get("sim", {})
    if "skipped" in sim:
        lines.append(f"simulator throughput: skipped ({sim['skipped']})")
    elif sim:
        lines.append(
            f"simulator throughput (`vtr bench sim`): {sim['steps_per_s']:.0f} steps/s "
            f"(render {sim['render_ms_median']:.2f} ms, physics {sim['physics_ms_median']:.2f} ms median)"
        )
    r = result["ratios"]
    lines += ["", "targets (issues 5, 11 and 19), at 1 thread:"]
    for key, (desc, op, threshold) in TARGETS.items():
        value, ok = r[key], r["meets_target"][key]
        shown = "n/a" if value is None else (f"{value:.3f}" if key.endswith("_ms") else f"{value:.2f}")
        mark = "n/a" if ok is None else ("MET" if ok else "missed")
        lines.append(f"  {desc:<50} {shown:>8}  target {op} {threshold:g}  {mark}")
    lines.append("retired ratio target (issue 19), reported:")
    for key, desc in OVERHEADS.items():
        shown = "n/a" if r.get(key) is None else f"{r[key]:+.1%}"
        lines.append(f"  {desc:<50} {shown:>8}")
    for model, other in result.get("also_models", {}).items():
        lines += [
            "",
            f"{model} ({other['gflop']:.3f} GFLOP), same run: whole step p50 / its inference p50 - 1",
        ]
        for key, variant in STEP_VARIANTS.items():
            pair = other["stages"]["pairs"][variant]
            lines.append(
                f"  {OVERHEADS[key]:<50} {other['step_overhead'][key]:>+8.1%}  ({pair['whole_step']['p50_ms']:.3f}"
                f" / {pair['inference']['p50_ms']:.3f} ms)"
            )
    return "\n".join(lines)


def _compute_lines(compute: dict[str, Any]) -> list[str]:
    """Each whole step's compute apart from its link, beside inference alone in the same loop."""
    if not compute:
        return []
    lines = [
        "",
        "  step compute (Repeater.step's own stage times), the link apart, inference alone in the same loop:",
        f"  {'variant':<24}{'compute p50':>12}{'p99':>8}{'link p50':>10}{'p99':>8}{'infer p50':>11}{'p99':>8}"
        f"{'compute/infer':>15}{'cpu p50':>9}{'p99':>8}",
    ]
    for name, c in compute.items():
        sc, link, inf = c["step_compute"], c["link"], c["inference"]
        cpu = c.get("step_compute_cpu")
        cpu_text = "" if cpu is None else f"{cpu['p50_ms']:>9.3f}{cpu['p99_ms']:>8.3f}"
        lines.append(
            f"  {name:<24}{sc['p50_ms']:>12.3f}{sc['p99_ms']:>8.3f}{link['p50_ms']:>10.3f}{link['p99_ms']:>8.3f}"
            f"{inf['p50_ms']:>11.3f}{inf['p99_ms']:>8.3f}{sc['p50_ms'] / inf['p50_ms']:>14.2f}x{cpu_text}"
        )
    lines.append("  (cpu: this thread's CPU time in the judgement and the policy, waits for a core left out)")
    return lines
