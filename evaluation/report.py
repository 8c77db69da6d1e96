"""A README-ready Results section from the JSON files of `vtr bench latency` and `vtr eval`.

python -m vtr.evaluation.report --latency out/latency.json --eval out/eval.json [--out RESULTS.md]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from vtr.benchmarks.latency_report import TARGETS
from vtr.runtime.atomic import write_text_atomic


def latency_section(lat: dict[str, Any]) -> list[str]:
    st = lat["stages"]
    lines = [
        "### Latency per control step (CPU)",
        "",
        f"`vtr bench latency --model {lat['model']} --threads {st['threads']}` on {lat['machine']['cores']} cores; "
        f"{lat['gflop']:.3f} GFLOP per step.",
        "",
        "| stage | p50 ms | p99 ms |",
        "|---|---|---|",
    ]
    for name, t in st["stages"].items():
        lines.append(f"| {name} | {t['p50_ms']:.3f} | {t['p99_ms']:.3f} |")
    z = lat.get("zmq", {})
    if "calls" in z:
        for name, t in z["calls"].items():
            label = (
                f"ZeroMQ {name} round trip"
                if name != "render_in_process"
                else "(simulator render, in process)"
            )
            lines.append(f"| {label} | {t['p50_ms']:.3f} | {t['p99_ms']:.3f} |")
    lines += [
        "",
        "| threads | backend | p50 ms | p99 ms | GFLOP/s | of matmul |",
        "|---|---|---|---|---|---|",
    ]
    for threads, entry in lat["backends"]["threads"].items():
        mm = entry["matmul"]
        lines.append(
            f"| {threads} | float32 matmul {mm['n']}^3 (reference) | | | {mm['best_gflops']:.1f} | 100% |"
        )
        for name, b in entry["backends"].items():
            if "skipped" in b:
                lines.append(f"| {threads} | {name} | skipped | | | |")
            else:
                lines.append(
                    f"| {threads} | {name} | {b['p50_ms']:.3f} | {b['p99_ms']:.3f} | {b['achieved_gflops']:.1f} "
                    f"| {b['fraction_of_matmul']:.0%} |"
                )
    mem, sim = lat.get("memory", {}), lat.get("sim", {})
    lines.append("")
    if "peak_rss_mb" in mem:
        lines.append(f"Runtime-only process (no torch): peak RSS {mem['peak_rss_mb']:.0f} MB.")
    if "steps_per_s" in sim:
        lines.append(
            f"Simulator (`vtr bench sim`): {sim['steps_per_s']:.0f} steps/s at the model's camera size."
        )
    r = lat["ratios"]
    lines += ["", "| target (issues 5 and 11, 1 thread) | measured | target | |", "|---|---|---|---|"]
    for key, (desc, op, threshold) in TARGETS.items():
        value, ok = r.get(key), r["meets_target"].get(key)  # results written before a target existed: n/a
        shown = (
            "n/a"
            if value is None
            else (f"{value:+.1%}" if key.startswith("step_overhead") else f"{value:.2f}")
        )
        lines.append(
            f"| {desc} | {shown} | {op} {threshold:g} | {'-' if ok is None else ('met' if ok else 'missed')} |"
        )
    return lines


def eval_section(ev: dict[str, Any]) -> list[str]:
    from vtr.evaluation.tables import markdown_report

    cfg = ev["config"]
    cmd = f"vtr eval --model {cfg['model']} --noise {cfg['noise']}"
    if cfg.get("routes"):
        cmd += " --routes " + " ".join(cfg["routes"])
    if cfg.get("e_m") is not None:
        cmd += f" --e-m {cfg['e_m']}"
    if cfg.get("oracle"):
        cmd += " --oracle"
    if cfg.get("viewnet"):
        cmd += f" --viewnet {cfg['viewnet']} --mpc-samples {cfg['mpc_samples']}"
    if cfg.get("ablation_model"):
        cmd += f" --ablation-model {cfg['ablation_model']}"
    body = markdown_report(ev).splitlines()
    return ["### Closed-loop tracking", "", f"`{cmd} --json ... --plots ...`", "", *body[1:]]


def build(latency: dict[str, Any] | None, evaluations: list[dict[str, Any]]) -> str:
    lines = ["## Results", ""]
    for evaluation in evaluations:
        lines += eval_section(evaluation) + [""]
    if latency is not None:
        lines += latency_section(latency) + [""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--latency", type=Path, default=None, help="JSON of vtr bench latency")
    parser.add_argument(
        "--eval", type=Path, nargs="*", default=[], help="JSON files of vtr eval (one section each)"
    )
    parser.add_argument("--out", type=Path, default=None, help="write here (default: stdout)")
    args = parser.parse_args(argv)
    if args.latency is None and not args.eval:
        parser.error("give --latency and/or --eval")
    lat = json.loads(args.latency.read_text()) if args.latency else None
    evs = [json.loads(p.read_text()) for p in args.eval]
    text = build(lat, evs)
    if args.out is None:
        print(text)
    else:
        write_text_atomic(args.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
