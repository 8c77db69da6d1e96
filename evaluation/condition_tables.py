"""Tables of condition-suite results (evaluation.condition_suite): one result's per-condition table, and a
comparison of several (``python -m vtr.evaluation.condition_tables RESULT.json ...``)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from vtr.evaluation.condition_run import step_compute_line
from vtr.evaluation.metrics import OFF_PATH_M


def markdown(result: dict[str, Any]) -> str:
    def f(x: float | None, scale: float = 1.0, digits: int = 1) -> str:
        return "-" if x is None else f"{x * scale:.{digits}f}"

    cfg = result["config"]
    lines = [
        f"Condition suite: routes {', '.join(result['routes'])}; seeds {cfg['seeds']}; step limit "
        f"{cfg['max_steps_factor']} x subgoals + 50. Completed = did what the condition expects: finished "
        "without touching anything (those that passed a taught subgoal more than "
        f"{OFF_PATH_M * 100:.0f} cm away are counted beside it), or, under box_on_path, stopped as blocked "
        "without touching the box (beside it: the robot's centre to the box's nearest face at the end; "
        "contact at 0.17 m); errors "
        "are means over completed runs that finished (nearest-point position error per taught pose, the paper's "
        "metric).",
        "",
        "| controller | model | condition | completed | mean err (mm) | max err (mm) | yaw (deg) | cross-track (mm) "
        "| final (mm / deg) | runs w/ contact | steps / taught | failures |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in result["table"]:
        fails = ", ".join(f"{k} {v}" for k, v in sorted(r["failure_causes"].items())) or "-"
        blocked = f" ({r['not_run']} not run: start or scene blocked)" if r["not_run"] else ""
        if r.get("box_face_m") is not None:
            blocked += f" (ended {r['box_face_m']:.2f} m from the box)"
        far = r.get("completed_off_path", 0)
        blocked += f" ({far} > {OFF_PATH_M * 100:.0f} cm off the path)" if far else ""
        lines.append(
            f"| {r['controller']} | {r['model']} | {r['condition']} | {r['completed']}/{r['runs']}{blocked} "
            f"| {f(r['mean_position_error_m'], 1e3)} | {f(r['max_position_error_m'], 1e3)} | {f(r['mean_yaw_error_deg'], 1, 2)} "
            f"| {f(r['cross_track_m'], 1e3)} | {f(r['final_position_m'], 1e3)} / {f(r['final_yaw_deg'], 1, 1)} "
            f"| {r['runs_with_contact']} | {f(r['steps_per_taught_step'], 1, 2)} | {fails} |"
        )
    if "step_compute" in result:  # results before session 18: none
        lines += ["", step_compute_line(result["step_compute"], cfg["workers"])]
    return "\n".join(lines) + "\n"


def comparison(results: list[dict[str, Any]]) -> str:
    """One Markdown table over several suite results: per condition, each (method, model)'s completed runs,
    then its mean error (mm) and steps per taught step over completed runs."""
    rows = [r for res in results for r in res["table"]]
    columns = list(dict.fromkeys((r["controller"], r["model"]) for r in rows))
    cell = {(r["controller"], r["model"], r["condition"]): r for r in rows}
    lines = [
        "| condition | " + " | ".join(f"{c} {m}" for c, m in columns) + " |",
        "|---|" + "---|" * len(columns),
    ]
    for cond in dict.fromkeys(r["condition"] for r in rows):
        cells = []
        for c, m in columns:
            r = cell.get((c, m, cond))
            if r is None:
                cells.append("")
                continue
            err = "-" if r["mean_position_error_m"] is None else f"{r['mean_position_error_m'] * 1e3:.1f} mm"
            ratio = "-" if r["steps_per_taught_step"] is None else f"{r['steps_per_taught_step']:.2f}x"
            cells.append(f"{r['completed']}/{r['runs']}, {err}, {ratio}")
        lines.append(f"| {cond} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def stops(results: list[dict[str, Any]]) -> str:
    """One Markdown table of how runs ended, per (controller, model, condition) over several suite results
    (issue 19's obstruction conditions): runs, finished on the route (metrics.off_route), stopped as
    blocked, runs with a contact, completed (did what the condition expects), and with a path box the
    robot's centre to its nearest face: at the end (min / median), and the closest it came (min)."""

    def spread(values: list[float]) -> str:
        return f"{min(values):.2f} / {float(np.median(values)):.2f}" if values else "-"

    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for res in results:
        for r in res["runs"]:
            if r["ran"]:
                groups.setdefault((r["controller"], r["model"], r["condition"]), []).append(r)
    lines = [
        "| controller | model | condition | runs | finished on route | blocked | runs w/ contact | completed "
        "| box face at the end (m, min / median) | closest to the box (m, min) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (ctrl, model, cond), rs in groups.items():
        on_route = sum(r["status"] == "finished" and r.get("on_route", False) for r in rs)
        blocked = sum(r["status"] == "blocked" for r in rs)
        contact = sum(r["contacts"] > 0 for r in rs)
        done = sum(r["completed"] for r in rs)
        at_end = [r["box_face_m"] for r in rs if r.get("box_face_m") is not None]
        closest = [r["box_closest_m"] for r in rs if r.get("box_closest_m") is not None]
        lines.append(
            f"| {ctrl} | {model} | {cond} | {len(rs)} | {on_route} | {blocked} | {contact} | {done} "
            f"| {spread(at_end)} | {f'{min(closest):.2f}' if closest else '-'} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m vtr.evaluation.condition_tables RESULT.json ...``: the comparison table of suite results."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument(
        "results", nargs="+", type=Path, help="JSON files written by vtr eval --suite conditions"
    )
    parser.add_argument("--stops", action="store_true", help="how runs ended (issue 19's stop table)")
    args = parser.parse_args(argv)
    try:
        results = [json.loads(p.read_text(encoding="utf-8")) for p in args.results]
    except (OSError, ValueError) as err:
        print(f"condition_tables: {err}", file=sys.stderr)
        return 2
    print(stops(results) if args.stops else comparison(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
