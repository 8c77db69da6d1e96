"""The MPC-vs-BC table (studies/mpc_vs_bc.py) from the study's scratch folder.

Reads ``eval/LABEL.json`` (`vtr eval --suite conditions --json`), ``offline/LABEL.json`` (`vtr train evaluate
--json` on houses the training never saw, commands as executed) and ``runs/NAME/report_sSTEPS.json`` (the
training's own held-out houses, labels as logged), where LABEL is ``NAME_sSTEPS`` or ``shipped``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from studies.mpc_vs_bc import RUNS, wilson


def _load(path: Path) -> dict[str, Any] | None:
    return json.loads(path.read_text()) if path.is_file() else None


def sign_test(a_only: int, b_only: int) -> float:
    """Two-sided exact sign test (McNemar) on the discordant pairs."""
    n = a_only + b_only
    if n == 0:
        return 1.0
    k = min(a_only, b_only)
    p = sum(math.comb(n, i) for i in range(k + 1)) / 2**n
    return min(1.0, 2 * p)


def summarise(doc: dict[str, Any]) -> dict[str, Any]:
    """Completion on the route, errors and pace over one evaluation's runs."""
    runs = [r for r in doc["runs"] if r.get("ran")]
    done = [r for r in runs if r["completed"]]
    fin = [r for r in runs if r.get("status") == "finished"]
    lo, hi = wilson(len(done), len(runs))

    def mean(rs: list[dict[str, Any]], key: str) -> float | None:
        return sum(r[key] for r in rs) / len(rs) if rs else None

    return {
        "n": len(runs),
        "completed": len(done),
        "finished": len(fin),
        "wilson": (lo, hi),
        "err_completed_mm": None if not done else 1e3 * mean(done, "position_error_m"),
        "err_finished_mm": None if not fin else 1e3 * mean(fin, "position_error_m"),
        "pace": mean(done, "steps_per_taught_step"),
        "by_run": {(r["route"], r["seed"]): bool(r["completed"]) for r in runs},
        "err_by_run": {(r["route"], r["seed"]): r["position_error_m"] for r in done},
    }


def _fmt(x: float | None, spec: str) -> str:
    return "-" if x is None else format(x, spec)


def _offline(root: Path, name: str, label: str, steps: str) -> tuple[str, str]:
    rep = _load(root / "runs" / name / f"report_s{steps}.json")
    off = _load(root / "offline" / f"{label}.json")

    def ratio(d: dict[str, Any] | None) -> str:
        if not d:
            return "-"
        d = d.get("velocitynet", d)
        return f"{d['mse_first_command']:.4f} ({d['ratio_to_baseline']:.3f}x)"

    return ratio(rep), ratio(off)


def render(root: Path, commands: str) -> str:
    rows, stats = [], {}
    order = {name: i for i, name in enumerate(RUNS)}

    def key(label: str) -> tuple[int, int, str]:
        name, _, steps = label.rpartition("_s")
        return (order.get(name, len(order)), int(steps) if steps.isdigit() else 0, label)

    labels = sorted((p.stem for p in (root / "eval").glob("*.json")), key=key)
    for label in labels:
        doc = _load(root / "eval" / f"{label}.json")
        if doc is None:
            continue
        s = summarise(doc)
        stats[label] = s
        name, _, steps = label.rpartition("_s")
        if label == "shipped":
            what, own, held = ("shipped model (40 houses + paper house, 9500 steps)", "-", "-")
        else:
            data, seed, flags = RUNS[name]
            loss = {"": "MPC (w1 0.8, w2 0.3)", "--w1 0": "BC (w1 0)", "--w2 0": "image only (w2 0)"}[flags]
            what = f"{data}, {loss}, seed {seed}, {steps} steps"
            own, held = _offline(root, name, label, steps)
        lo, hi = s["wilson"]
        rows.append(
            f"| {what} | **{s['completed']}/{s['n']}** ({100 * s['completed'] / max(1, s['n']):.0f}%, "
            f"{100 * lo:.0f}-{100 * hi:.0f}%) | {s['finished']}/{s['n']} | {_fmt(s['err_completed_mm'], '.1f')} | "
            f"{_fmt(s['err_finished_mm'], '.1f')} | {_fmt(s['pace'], '.2f')} | {own} | {held} |"
        )
    head = [
        "| model | completed on the route (95% Wilson) | finished | mean error, completed (mm) | "
        "mean error, finished (mm) | steps per taught step | offline: own held-out houses, labels as logged "
        "(x mean-command) | offline: houses 5720-5722, executed commands (x mean-command) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    pairs = []
    for label in labels:
        if "_mpc_" not in label:
            continue
        other = label.replace("_mpc_", "_bc_")
        if other in stats:
            a, b = stats[label]["by_run"], stats[other]["by_run"]
            keys = sorted(set(a) & set(b))
            a_only = sum(a[k] and not b[k] for k in keys)
            b_only = sum(b[k] and not a[k] for k in keys)
            both = [k for k in keys if a[k] and b[k]]
            ea, eb = stats[label]["err_by_run"], stats[other]["err_by_run"]
            err = "-"
            if both:
                err = (
                    f"{1e3 * sum(ea[k] for k in both) / len(both):.1f} / "
                    f"{1e3 * sum(eb[k] for k in both) / len(both):.1f} "
                    f"(MPC lower in {sum(ea[k] < eb[k] for k in both)} of {len(both)})"
                )
            pairs.append(
                f"| {label} vs {other} | {len(keys)} | {a_only} | {b_only} | {sign_test(a_only, b_only):.2f} | "
                f"{err} |"
            )
    out = ["```bash", commands, "```", "", *head, *rows, ""]
    if pairs:
        out += [
            "Paired (same route, same noise seed): runs only MPC completed, runs only BC completed, and the "
            "exact two-sided sign test on those discordant runs; and the mean error of the runs both completed.",
            "",
            "| pair | paired runs | only MPC completed | only BC completed | p | mean error where both completed, "
            "MPC / BC (mm) |",
            "|---|---|---|---|---|---|",
            *pairs,
            "",
        ]
    return "\n".join(out)


def render_seeds(eval_dir: Path, runs_dir: Path) -> str:
    """The GPU lease's runs (studies/train_on_gpu.py): per model and seed, then MPC against BC pooled over the
    seeds, paired by (training seed, route, noise seed). Files: eval_dir/{data}_{loss}_s{seed}.json and
    runs_dir/{data}_{loss}_s{seed}/report.json + metrics.jsonl (steps reached)."""
    rows, stats = [], {}
    for path in sorted(eval_dir.glob("*_s[0-9].json")):
        label = path.stem
        data, loss, seed = label.rsplit("_", 2)
        doc = _load(path)
        if doc is None or loss not in ("mpc", "bc"):
            continue
        s = stats[label] = summarise(doc)
        rep = _load(runs_dir / label / "report.json") or {}
        steps = []
        for stage in (f"{label}_a", label):
            lines = (runs_dir / stage / "metrics.jsonl").read_text().splitlines()
            steps.append(max(json.loads(x).get("step", 0) for x in lines))
        rows.append(
            f"| {data} | {'MPC (w1 0.8, w2 0.3)' if loss == 'mpc' else 'BC (w1 0)'} | {seed[1:]} | "
            f"{steps[0]} + {steps[1]} | {_fmt(rep.get('ratio_to_baseline'), '.3f')} | "
            f"{s['completed']}/{s['n']} | {_fmt(s['err_completed_mm'], '.1f')} | {_fmt(s['pace'], '.2f')} |"
        )
    out = [
        "| data | loss | seed | steps reached (batch 64: lr 1e-3 + 3e-4) | offline: first command x mean-command "
        "| completed on the route | mean error, completed (mm) | steps per taught step |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        "| data | MPC completed | BC completed | paired runs | only MPC | only BC | sign test p | mean error where "
        "both completed, MPC / BC (mm) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for data in sorted({k.rsplit("_", 2)[0] for k in stats}):
        a, b, ea, eb = {}, {}, {}, {}
        for label, s in stats.items():
            d, loss, seed = label.rsplit("_", 2)
            if d != data:
                continue
            runs, errs = (a, ea) if loss == "mpc" else (b, eb)
            runs.update({(seed, *k): v for k, v in s["by_run"].items()})
            errs.update({(seed, *k): v for k, v in s["err_by_run"].items()})
        keys = sorted(set(a) & set(b))
        a_only = sum(a[k] and not b[k] for k in keys)
        b_only = sum(b[k] and not a[k] for k in keys)
        both = [k for k in keys if a[k] and b[k]]
        err = "-"
        if both:
            err = (
                f"{1e3 * sum(ea[k] for k in both) / len(both):.1f} / {1e3 * sum(eb[k] for k in both) / len(both):.1f}"
                f" (MPC lower in {sum(ea[k] < eb[k] for k in both)} of {len(both)})"
            )
        out.append(
            f"| {data} | {sum(a[k] for k in keys)}/{len(keys)} | {sum(b[k] for k in keys)}/{len(keys)} | {len(keys)} "
            f"| {a_only} | {b_only} | {sign_test(a_only, b_only):.2f} | {err} |"
        )
    return "\n".join(out) + "\n"
