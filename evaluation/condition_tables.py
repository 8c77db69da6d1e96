"""Tables of condition-suite results (evaluation.condition_suite): one result's per-condition table, and a
comparison of several (``python -m vtr.evaluation.condition_tables RESULT.json ...``)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

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
        "are means over completed runs (nearest-point position error per taught pose, the paper's metric).",
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


def main(argv: list[str] | None = None) -> int:
    """``python -m vtr.evaluation.condition_tables RESULT.json ...``: the comparison table of suite results."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument(
        "results", nargs="+", type=Path, help="JSON files written by vtr eval --suite conditions"
    )
    args = parser.parse_args(argv)
    try:
        results = [json.loads(p.read_text(encoding="utf-8")) for p in args.results]
    except (OSError, ValueError) as err:
        print(f"condition_tables: {err}", file=sys.stderr)
        return 2
    print(comparison(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
