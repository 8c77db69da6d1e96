"""`vtr eval --run RUN.mcap --taught ROUTE.npz`: score a run recorded with `vtr repeat --mcap` on any robot.

The run's poses (where the robot reported them) are compared with the taught route's poses by the same metrics
as the simulator evaluation (evaluation.metrics.route_metrics); completion comes from the run's summary.
A file that is not such a run is one line and exit 2 (runtime.mcap_read); a damaged one is scored as far as it
reads, with a warning on stderr. ``--plots DIR`` draws the run (evaluation.run_plots), even one without poses,
which cannot be scored: then what is missing is one line and the exit 0.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from vtr.evaluation import metrics
from vtr.runtime.mcap_read import RecordedRun, read_run
from vtr.runtime.route import Route


def score_recorded_run(run: RecordedRun, route: Route) -> dict[str, Any]:
    """Metrics of a recorded run against its taught route; ValueError when either lacks poses."""
    known = np.isfinite(run.poses).all(axis=1)
    if not known.any():
        raise ValueError("the run has no poses (the robot reported none): only its summary can be shown")
    if not np.isfinite(route.poses).all():
        raise ValueError("the taught route has unknown poses: nothing to compare the run with")
    summary = run.summary or {}
    reached = int(summary.get("subgoals_reached", max((s.get("subgoal", 0) for s in run.steps), default=0)))
    if reached > len(route):
        raise ValueError(
            f"the run reached {reached} subgoals but the taught route has {len(route)}: is --taught the route "
            "it repeated?"
        )
    out = metrics.route_metrics(route.poses, run.poses[known], run.commands, reached)
    out.update(
        status=summary.get("status"),
        subgoals_reached=reached,
        subgoals=len(route),
        steps=int(summary.get("steps", len(run.commands))),
        poses_known=int(known.sum()),
        images=run.image_count,
    )
    if run.warnings:
        out["warnings"] = list(run.warnings)  # damage: scored as far as the file reads
    return out


def run_cli(args: Any) -> int:
    if args.taught is None:
        print("vtr eval: --run needs --taught ROUTE.npz (the route the run repeated)", file=sys.stderr)
        return 2
    try:
        route = Route.load(args.taught)
        run = read_run(args.run)
    except (OSError, ValueError) as exc:
        print(f"vtr eval: {exc}", file=sys.stderr)
        return 2
    plots: list[Path] = []
    if getattr(args, "plots_dir", None) is not None:  # drawn first: a run that cannot be scored can be seen
        from vtr.evaluation.run_plots import write_run_plots

        try:
            plots, missing = write_run_plots(run, route, Path(args.plots_dir), Path(args.run).stem)
        except OSError as exc:  # a file where the folder should be, a read-only place
            print(f"vtr eval: --plots {args.plots_dir}: {exc.strerror or exc}", file=sys.stderr)
            return 2
        for path in plots:
            print(f"vtr eval: wrote {path}", file=sys.stderr)
        if missing:
            print(f"vtr eval: {args.run}: {missing}", file=sys.stderr)
    try:
        result = score_recorded_run(run, route)
    except ValueError as exc:  # one line: the run's damage, when there was some, said in it
        if plots and (not np.isfinite(run.poses).all(axis=1).any() or not np.isfinite(route.poses).all()):
            _warn(run)
            return 0  # asked for pictures of a run without poses: drawn, and what is missing said
        damage = f" ({'; '.join(run.warnings)})" if run.warnings else ""
        print(f"vtr eval: {args.run}: {exc}{damage}", file=sys.stderr)
        return 2
    _warn(run)
    if plots:
        result["plots"] = [str(p) for p in plots]
    text = json.dumps(result, indent=2, default=float)
    if args.json_path is not None:
        from vtr.runtime.atomic import write_text_atomic

        write_text_atomic(Path(args.json_path), text)
    print(text)
    return 0


def _warn(run: RecordedRun) -> None:
    for warning in run.warnings:
        print(f"vtr eval: warning: {warning}", file=sys.stderr)
