"""The evaluation's plots in the paper's style: paths over the house, error and yaw per subgoal."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime.atomic import atomic_path


def draw_house(ax: Any, house: str = "house", labels: bool = True) -> bool:
    """Draw ``house`` (a map name, path or random:SEED) top-down: walls dark, furniture light, room names.

    Returns False (and draws nothing) when the simulator's house cannot be loaded: a plot without a floor
    plan is still a plot.
    """
    try:
        from vtr.sim2d import load_house

        h = load_house(house)
        seg = h.segments
        walls = np.asarray(seg.is_wall, dtype=bool)
        a, b = np.asarray(seg.a), np.asarray(seg.b)
    except Exception:
        return False
    for mask, colour, width in ((~walls, "0.7", 0.8), (walls, "0.25", 1.6)):
        for p, q in zip(a[mask], b[mask], strict=True):
            ax.plot([p[0], q[0]], [p[1], q[1]], color=colour, lw=width, zorder=1)
    for room in h.rooms if labels else ():
        c = np.asarray(room.polygon, dtype=np.float64).mean(axis=0)
        ax.text(
            c[0], c[1], room.name, color="0.55", fontsize=8, ha="center", va="center", zorder=1, clip_on=True
        )
    return True


def write_plots(result: dict[str, Any], out_dir: Path) -> list[Path]:
    """Per route: taught vs repeated x-y over the house; error per subgoal; yaw per subgoal for rotation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    colours = {
        "velocitynet": "tab:red",
        "velocitynet_int8": "tab:orange",
        "ablation_w2_0": "tab:purple",
        "online_mpc": "tab:green",
        "open_loop": "tab:gray",
        "pose_oracle": "tab:olive",
    }
    for r in result["routes"]:
        taught = np.asarray(r["taught_poses"])
        runs = r["scenarios"].get("noise", {})
        fig, ax = plt.subplots(figsize=(6.5, 7))
        draw_house(ax)
        ax.scatter(taught[:, 0], taught[:, 1], s=10, color="tab:blue", label="taught (subgoals)", zorder=3)
        for m, run in runs.items():
            rep = np.asarray(run["repeated_poses"])
            ax.scatter(rep[:, 0], rep[:, 1], s=4, color=colours.get(m, "k"), label=f"repeated: {m}", zorder=4)
        frame_route(ax, taught)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"{r['name']}: taught vs repeated (noise {result['config']['noise']})")
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2, frameon=False)
        written.append(save_figure(fig, out_dir / f"{r['name']}_path.png"))

        rotation = r["name"] == "rotation" or any(run["rotation_only"] for run in runs.values())
        fig, ax = plt.subplots(figsize=(7, 3.5))
        for m, run in runs.items():
            err = run["per_subgoal_yaw_error_deg" if rotation else "per_subgoal_position_error_m"]
            ax.plot(np.arange(len(err)), err, ".-", ms=3, lw=0.8, color=colours.get(m, "k"), label=m)
        ax.set_xlabel("subgoal index")
        ax.set_ylabel("yaw error (deg)" if rotation else "position error (m)")
        ax.set_title(f"{r['name']}: nearest-point error per subgoal")
        ax.legend(fontsize=7)
        written.append(save_figure(fig, out_dir / f"{r['name']}_error.png"))

        if rotation:
            fig, ax = plt.subplots(figsize=(7, 3.5))
            idx = np.arange(len(taught))
            ax.scatter(idx, np.degrees(np.unwrap(taught[:, 2])), s=8, color="tab:blue", label="taught")
            for m, run in runs.items():
                sw = run.get("switch_poses")
                if sw:
                    yaw = np.degrees(np.unwrap(np.asarray(sw["poses"])[:, 2]))
                    ax.scatter(sw["index"], yaw, s=4, color=colours.get(m, "k"), label=f"repeated: {m}")
            ax.set_xlabel("subgoal index")
            ax.set_ylabel("yaw (deg)")
            ax.set_title(f"{r['name']}: yaw per subgoal (repeated: at the switch to the next subgoal)")
            ax.legend(fontsize=7)
            written.append(save_figure(fig, out_dir / f"{r['name']}_yaw.png"))
    return written


def frame_route(ax: Any, taught: np.ndarray, margin: float = 1.0) -> None:
    """Zoom on the route with a margin of house around it (at least 3 m wide, equal axes)."""
    lo, hi = taught[:, :2].min(axis=0) - margin, taught[:, :2].max(axis=0) + margin
    centre, half = (lo + hi) / 2, max(1.5, *(hi - lo) / 2)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_aspect("equal", adjustable="box")


def save_figure(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path
