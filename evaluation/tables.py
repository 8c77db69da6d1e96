"""The evaluation's Markdown report: the paper's Tables 1 and 2 beside ours, then every route and method."""

from __future__ import annotations

from typing import Any

from vtr.evaluation.scoring import PAPER, paper_stat


def _fmt(x: float | None, unit: str = "") -> str:
    if x is None:
        return "-"
    if unit == "deg":
        return f"{x:.3f}"
    return f"{x:.2e}" if abs(x) < 1e-3 and x != 0 else f"{x:.4f}"


def markdown_report(result: dict[str, Any]) -> str:
    """The paper's Tables 1 and 2 beside ours, then every route and method."""
    cfg = result["config"]
    routes = {r["name"]: r for r in result["routes"]}
    lines = [
        "## Closed-loop tracking vs the paper",
        "",
        f"Repeat with actuation noise {cfg['noise']} (simulator level: a per-run bias of {cfg['noise']:.0%} in speed scale and "
        f"{0.5 * cfg['noise']:.3f} rad/m of curvature drift, plus {cfg['noise']:.0%} per-step jitter, 1 sigma each), "
        f"from the taught start. e_m: {'calibrated per route' if cfg['e_m'] is None else cfg['e_m']}.",
        "",
    ]
    order = ("velocitynet", "velocitynet_int8", "ablation_w2_0", "online_mpc", "open_loop", "pose_oracle")
    methods = [m for m in order if any(m in r["scenarios"].get("noise", {}) for r in routes.values())]
    for title, names, unit in (
        ("Table 1: nearest-point position error (m)", ("translation", "translation_rotation"), "m"),
        ("Table 2: nearest yaw error, pure rotation (deg)", ("rotation",), "deg"),
    ):
        present = [n for n in names if n in routes]
        if not present:
            continue
        lines += [f"### {title}", ""]
        header = "| statistic |"
        sep = "|---|"
        for n in present:
            header += f" paper {n} |" + "".join(f" {m} {n} |" for m in methods)
            sep += "---|" * (1 + len(methods))
        lines += [header, sep]
        for stat in ("min", "max", "mean", "std"):
            label = "MAE" if (stat == "mean" and unit == "deg") else stat
            row = f"| {label} |"
            for n in present:
                row += f" {_fmt(PAPER[n][stat], unit)} |"
                for m in methods:
                    s = paper_stat(routes[n], m)
                    row += f" {_fmt(None if s is None else s[stat], unit)} |"
            lines.append(row)
        lines.append("")
    for scen in ("noise", "offset"):
        if not any(scen in r["scenarios"] for r in routes.values()):
            continue
        what = (
            f"actuation noise {cfg['noise']}"
            if scen == "noise"
            else f"start offset dx={cfg['offset'][0]} m, dy={cfg['offset'][1]} m, dyaw={cfg['offset'][2]} deg, no noise"
        )
        lines += [
            f"### Every route: {what}",
            "",
            "| route | method | done | completion | mean err (m) | max err (m) | yaw MAE (deg) | cross-track (m) "
            "| final (m) | steps | sim time (s) | mean abs dv | mean abs dw | policy ms |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for name, r in routes.items():
            for m, run in r["scenarios"].get(scen, {}).items():
                pm = run.get("policy_ms", {}).get("p50")
                lines.append(
                    f"| {name} | {m} | {'yes' if run['completed'] else 'no'} | {run['completion']:.0%} "
                    f"| {_fmt(run['position_error_m']['mean'])} | {_fmt(run['position_error_m']['max'])} "
                    f"| {run['yaw_error_deg']['mean']:.3f} | {_fmt(run['mean_cross_track_error_m'])} "
                    f"| {_fmt(run['final_pose_error']['position_m'])} | {run['steps']} | {run['sim_time_s']:.1f} "
                    f"| {run['smoothness']['mean_abs_dv']:.4f} | {run['smoothness']['mean_abs_dw']:.4f} "
                    f"| {'-' if pm is None else f'{pm:.2f}'} |"
                )
        lines.append("")
    agg = result["aggregate"]
    lines += [
        "### Aggregate",
        "",
        "| scenario | method | completed | mean err (m) | cross-track (m) | policy ms p50 |",
        "|---|---|---|---|---|---|",
    ]
    for scen, by_method in agg.items():
        for m, a in by_method.items():
            pm = a["policy_ms_p50"]
            lines.append(
                f"| {scen} | {m} | {a['completed']}/{a['routes']} | {_fmt(a['mean_position_error_m'])} "
                f"| {_fmt(a['mean_cross_track_error_m'])} | {'-' if pm is None else f'{pm:.2f}'} |"
            )
    if result.get("notes"):
        lines += ["", "Not run: " + "; ".join(result["notes"]) + "."]
    lines += ["", "### Bar (issue 5)", ""]
    for key, ok in result["bar"].items():
        lines.append(f"- {key}: {'-' if ok is None else ('met' if ok else 'MISSED')}")
    return "\n".join(lines) + "\n"
