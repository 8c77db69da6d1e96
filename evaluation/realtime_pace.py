"""`vtr eval --suite pace`: repeat taught routes on a wall-clock robot and compare the time with the teach's.

Issue 19's pace target: a repeat on a realtime robot takes at most 1.15x the taught driving time, and at most
1.15 control steps per taught step. A lockstep simulator cannot show this (its clock waits for the runtime), so
each route is taught on a lockstep simulator (no noise, as `vtr teach`), then repeated by `vtr repeat`'s own
code (``runtime.daemon.run``, the defaults of `vtr repeat` unless ``--motion`` says otherwise) against a
simulator in ``--mode realtime`` with actuation noise, one reset seed per run. The taught time is the route's
(``runtime.status_line.taught_seconds``: what the status line shows); the repeat's is the run summary's wall time.
The path is scored from the poses the robot reported at each step, by the simulator evaluation's metrics.

The runtime and the simulator share the machine's cores: on a loaded machine the wall clock also measures the
load, so the load average at the start and end is written beside the figures. A finished run counts as on the
route as every suite counts it (``evaluation.metrics.off_route``); ``--json`` writes the rows and, beside them,
the table as Markdown.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

import vtr

REPO = Path(vtr.__file__).resolve().parents[1]
DEFAULT_MODEL = str(REPO / "models" / "velocitynet.onnx")


def teach_route(script: Path, out: Path) -> None:
    """Drive ``script`` once on a lockstep simulator (the paper-style house, no noise) and save the route."""
    from vtr.runtime.teach import TeachConfig, TeachRunConfig, run
    from vtr.sim2d.server import ServerConfig, start_server_process

    server = start_server_process(ServerConfig(bind="tcp://127.0.0.1:*"))
    try:
        run(TeachRunConfig(sim=server.endpoint, route=str(script), out=str(out), teach=TeachConfig()))
    finally:
        server.terminate()


def _repeat_config(endpoint: str, model: str, route: Path, log: Path, motion: str | None, seed: int) -> Any:
    """`vtr repeat`'s configuration from its settings' defaults, as the command line builds it."""
    from vtr.runtime.daemon import config_from_settings
    from vtr.runtime.settings import default, for_command

    values = {s.name: default(s.name) for s in for_command("repeat")}
    values.update({"robot.address": endpoint, "repeat.model": model, "repeat.route": str(route)})
    values.update({"repeat.motion": motion, "repeat.log": str(log), "repeat.json": True})
    return replace(config_from_settings(values), seed=seed)


def repeat_realtime(route: Path, model: str, seed: int, noise: float, motion: str | None, log: Path) -> dict:
    """One repeat of ``route`` on a realtime simulator; the summary, the taught time and the path's metrics."""
    from vtr.evaluation import metrics
    from vtr.runtime.daemon import run
    from vtr.runtime.route import Route
    from vtr.runtime.status_line import taught_seconds
    from vtr.sim2d.config import SimConfig
    from vtr.sim2d.server import ServerConfig, start_server_process

    cfg = ServerConfig(bind="tcp://127.0.0.1:*", mode="realtime", sim=SimConfig(noise=noise))
    server = start_server_process(cfg)
    try:
        summary = run(_repeat_config(server.endpoint, model, route, log, motion, seed))
    finally:
        server.terminate()
    taught = Route.load(route)
    steps = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    poses = np.array([s["pose"] for s in steps if s.get("pose") is not None], dtype=float)
    commands = np.array([[s.get("v", 0.0), s.get("w", 0.0)] for s in steps if "v" in s], dtype=float)
    scored = metrics.route_metrics(taught.poses, poses, commands, summary.subgoals_reached)
    taught_s = taught_seconds(taught)
    taught_steps = (len(taught) - 1) * (taught.steps_between or 1)
    return {
        "status": summary.status.value,
        "subgoals": f"{summary.subgoals_reached}/{summary.subgoals_total}",
        "wall_s": round(summary.wall_time_s, 2),
        "taught_s": None if taught_s is None else round(taught_s, 2),
        "time_ratio": None if not taught_s else round(summary.wall_time_s / taught_s, 3),
        "steps": summary.steps,
        "steps_ratio": round(summary.steps / taught_steps, 3) if taught_steps else None,
        "mean_error_mm": round(1000 * scored["position_error_m"]["mean"], 1),
        "final_error_mm": round(1000 * scored["final_pose_error"]["position_m"], 1),
        "waited_steps": summary.waited_steps,
        # finished on the route, as every suite counts a completion (evaluation.metrics.off_route)
        "off_route": metrics.off_route(
            scored["position_error_m"]["mean"], scored["final_pose_error"]["position_m"]
        )
        if summary.status.value == "finished"
        else "",
    }


def pace(
    routes: list[Path], seeds: list[int], motions: list[str | None], model: str, noise: float, work: Path
) -> list[dict]:
    from vtr.runtime.status_line import Progress

    rows, progress = [], Progress("pace", len(routes) * len(seeds) * len(motions))
    for script in routes:
        taught = work / f"{script.stem}.npz"
        teach_route(script, taught)
        for motion in motions:
            for seed in seeds:
                log = work / f"{script.stem}_{motion or 'default'}_{seed}.jsonl"
                row = repeat_realtime(taught, model, seed, noise, motion, log)
                rows.append({"route": script.stem, "motion": motion or "default", "seed": seed, **row})
                progress.advance(f"{script.stem} {row['status']} {row['time_ratio']}x")
    progress.close()
    return rows


def _median(values: list[float]) -> float | None:
    return round(float(np.median(values)), 3) if values else None


def table(rows: list[dict]) -> str:
    """Per motion: runs, finished, finished on the route (mean nearest-point error <= 3 cm, final position within
    5 cm: ``evaluation.metrics.off_route``), the time and step ratios of the finished runs (median / max) and
    their mean error."""
    lines = [
        "| motion | runs | finished | on the route | wall / taught time (median / max) "
        "| steps / taught steps (median / max) | mean error, finished (mm) |",
        "|---|---|---|---|---|---|---|",
    ]
    for motion in dict.fromkeys(r["motion"] for r in rows):
        mine = [r for r in rows if r["motion"] == motion]
        done = [r for r in mine if r["status"] == "finished"]
        on_route = sum(1 for r in done if not r.get("off_route"))
        times = [r["time_ratio"] for r in done if r["time_ratio"] is not None]
        steps = [r["steps_ratio"] for r in done if r["steps_ratio"] is not None]
        err = np.mean([r["mean_error_mm"] for r in done]) if done else float("nan")
        lines.append(
            f"| {motion} | {len(mine)} | {len(done)} | {on_route} | {_median(times)} / {max(times, default=None)} "
            f"| {_median(steps)} / {max(steps, default=None)} | {err:.1f} |"
        )
    return "\n".join(lines)


def write_outputs(json_path: Path, rows: list[dict], report: str) -> Path:
    """The rows as JSON at ``json_path`` and the printed report as Markdown beside it (``.md``), as the other
    suites write theirs; returns the Markdown's path."""
    from vtr.runtime.atomic import write_text_atomic

    md = json_path.with_suffix(".md")
    write_text_atomic(json_path, json.dumps(rows, indent=1))
    write_text_atomic(md, report + "\n")
    return md


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The pace's one option; `vtr eval` owns --routes, --seeds, --noise, --model and --json."""
    g = parser.add_argument_group("realtime pace (--suite pace: --routes, --seeds, --noise, --model, --json)")
    g.add_argument(
        "--motion",
        nargs="+",
        default=["default"],
        choices=["default", "stop-and-go", "continuous"],
        help="repeat motions to compare (default: default, what `vtr repeat` does)",
    )


def run_cli(args: argparse.Namespace) -> int:
    from vtr.evaluation.condition_suite import route_paths

    try:
        routes = route_paths(tuple(args.routes))
    except ValueError as exc:
        print(f"vtr eval: {exc}", file=sys.stderr)
        return 2
    if not routes:
        print(f"vtr eval: no ROUTE.json files in {' '.join(args.routes)}", file=sys.stderr)
        return 2
    motions = [None if m == "default" else m for m in args.motion]
    model = str(args.model) if args.model else DEFAULT_MODEL
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        rows = pace(routes, list(args.seeds), motions, model, float(args.noise), Path(tmp))
    report = f"{table(rows)}\nload average {load:.1f} at the start, {os.getloadavg()[0]:.1f} at the end"
    print(report)
    if args.json_path:
        md = write_outputs(Path(args.json_path), rows, report)
        print(f"wrote {args.json_path} and {md}")
    return 0
