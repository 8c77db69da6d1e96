"""Pictures of one recorded run (`vtr eval --run RUN.mcap --taught ROUTE.npz --plots DIR`): the taught and
repeated path, the error along the route, and the commands over time, as PNGs in the style of the simulator
evaluation's (evaluation.plots).

A run records what its robot reported: without poses there is no path and no position error to draw, without a
taught route's poses nothing to compare with; what can be drawn is, and :func:`write_run_plots` says in one line
what could not.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vtr.evaluation.metrics import nearest_point_errors
from vtr.evaluation.plots import draw_house, frame_route, save_figure
from vtr.runtime.mcap_read import RecordedRun
from vtr.runtime.route import Route


def write_run_plots(run: RecordedRun, route: Route, out_dir: Path, stem: str) -> tuple[list[Path], str]:
    """PNGs ``<stem>_path.png`` (taught and repeated x-y), ``<stem>_error.png`` (position error per taught
    subgoal, image error per step) and ``<stem>_commands.png`` (v, w against time) in ``out_dir``, each where
    the run holds what it needs; returns the files written and what was missing ("" when nothing was)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    known = np.isfinite(run.poses).all(axis=1) if len(run.poses) else np.zeros(0, bool)
    repeated = run.poses[known]
    taught = route.poses if len(route.poses) and np.isfinite(route.poses).all() else None
    missing = []
    if not len(run.commands):
        missing.append("control steps")
    if not len(repeated):
        missing.append("the run's poses (the robot reported none): no path, no position error")
    if taught is None:
        missing.append("the taught route's poses: no taught path, no position error")
    written = []

    if len(repeated) or taught is not None:
        fig, ax = plt.subplots(figsize=(6.5, 7))
        if route.map:
            draw_house(ax, route.map)
        if taught is not None:
            ax.plot(taught[:, 0], taught[:, 1], "-", lw=0.8, color="tab:blue", alpha=0.5, zorder=2)
            ax.scatter(
                taught[:, 0], taught[:, 1], s=10, color="tab:blue", label="taught (subgoals)", zorder=3
            )
        if len(repeated):
            ax.plot(
                repeated[:, 0],
                repeated[:, 1],
                ".-",
                ms=2,
                lw=0.6,
                color="tab:red",
                label="repeated",
                zorder=4,
            )
            ax.scatter(*repeated[0, :2], s=30, marker="o", color="k", label="start", zorder=5)
        frame_route(ax, taught if taught is not None else repeated)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"{stem}: taught vs repeated ({_status(run)})")
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3, frameon=False)
        written.append(save_figure(fig, out_dir / f"{stem}_path.png"))

    position = taught is not None and len(repeated) > 0
    image = np.isfinite(run.errors)
    if position or image.any():
        panels = int(position) + int(image.any())
        fig, axes = plt.subplots(panels, 1, figsize=(7, 2.8 * panels), squeeze=False)
        axes = list(axes[:, 0])
        if position:
            ax = axes.pop(0)
            err = nearest_point_errors(taught[:, :2], repeated[:, :2])
            ax.plot(np.arange(len(err)), err, ".-", ms=3, lw=0.8, color="tab:red")
            ax.set_xlabel("taught subgoal")
            ax.set_ylabel("position error (m)")
            ax.set_title(f"{stem}: nearest-point error along the route (mean {err.mean():.3f} m)")
        if image.any():
            ax = axes.pop(0)
            ax.plot(run.times[image], run.errors[image], lw=0.8, color="tab:purple")
            ax.set_xlabel("time (s)")
            ax.set_ylabel("image error")
            ax.set_title("image error to the subgoal steered to, per control step")
        written.append(save_figure(fig, out_dir / f"{stem}_error.png"))
    elif len(run.commands):
        missing.append("image errors")

    if len(run.commands):
        fig, (ax_v, ax_w) = plt.subplots(2, 1, figsize=(7, 4.5), sharex=True)
        ax_v.step(run.times, run.commands[:, 0], where="post", lw=0.8, color="tab:green")
        ax_v.set_ylabel("v (m/s)")
        ax_v.set_title(f"{stem}: commands ({len(run.commands)} steps recorded)")
        ax_w.step(run.times, run.commands[:, 1], where="post", lw=0.8, color="tab:orange")
        ax_w.set_ylabel("w (rad/s)")
        ax_w.set_xlabel("time (s)")
        for ax in (ax_v, ax_w):
            ax.axhline(0.0, color="0.6", lw=0.5)
        written.append(save_figure(fig, out_dir / f"{stem}_commands.png"))
    return written, ("not in the run: " + "; ".join(missing)) if missing else ""


def _status(run: RecordedRun) -> str:
    summary = run.summary or {}
    status = summary.get("status") or "no summary"
    reached = summary.get("subgoals_reached")
    return f"{status}, {reached} subgoals reached" if reached is not None else str(status)
