"""`vtr demo`: the whole system in under a minute, with no torch.

1. start the simulator server in a child process on loopback (a free port);
2. teach the paper's translation + rotation route over ZeroMQ (`runtime.teach`);
3. repeat it with the shipped VelocityNet (`runtime.repeater.Repeater`, ONNX on onnxruntime), and replay the
   taught commands blind for comparison;
4. print the paper-style error table and write a PNG of the taught and repeated paths (its only file);
5. shut the server down, also on errors and Ctrl-C.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from vtr.evaluation import metrics
from vtr.models import find_model
from vtr.runtime.atomic import atomic_path
from vtr.runtime.cliargs import add_config_arguments, config_from_args, opt
from vtr.runtime.contracts import Observation
from vtr.sim2d.routes import ROUTES_DIR

DEFAULT_ROUTE = "translation_rotation"


@dataclass
class DemoConfig:
    """Settings of `vtr demo`."""

    model: Path | None = opt(None, "VelocityNet ONNX (default: the shipped models/velocitynet.onnx)")
    route: str = opt(DEFAULT_ROUTE, "route name in sim2d/routes, or a ROUTE.json path")
    noise: float = opt(0.05, "actuation noise of the simulator (teach and repeat alike)")
    seed: int = opt(0, "actuation noise seed of the repeat")
    out: Path = opt(Path("demo_out"), "folder for the PNG (the only file the demo writes)")
    threads: int = opt(1, "onnxruntime intra-op threads")
    open_loop: bool = opt(True, "also replay the taught commands blind, to show what vision corrects")
    timeout_s: float = opt(5.0, "seconds to wait for each simulator reply", flag="--timeout")

    def __post_init__(self) -> None:
        if not 0.0 <= self.noise <= 1.0:
            raise ValueError(f"noise must be in [0, 1], got {self.noise}")
        if self.threads < 1:
            raise ValueError(f"threads must be >= 1, got {self.threads}")
        if not self.timeout_s > 0:
            raise ValueError(f"timeout must be positive, got {self.timeout_s}")
        if not _route_path(self.route).is_file():
            names = ", ".join(p.stem for p in sorted(ROUTES_DIR.glob("*.json")))
            raise ValueError(f"route not found: {self.route}; name one of {names} or a ROUTE.json file")


def _route_path(route: str) -> Path:
    path = Path(route)
    if path.suffix == ".json":
        return path
    return ROUTES_DIR / f"{route}.json"


class _Say:
    """Numbered progress lines with elapsed time, flushed at once (the demo is watched live)."""

    def __init__(self) -> None:
        self.t0 = time.perf_counter()

    def __call__(self, text: str) -> None:
        print(f"[{time.perf_counter() - self.t0:5.1f} s] {text}", flush=True)


def run(cfg: DemoConfig) -> dict[str, Any]:
    """Run the demo; returns every number it printed."""
    import pymunk  # noqa: F401 - the simulator runs in a child process: say it is missing here, in one line

    from vtr.runtime.client import SimClient
    from vtr.runtime.light import LightMatchedPolicy
    from vtr.runtime.policy import OnnxPolicy
    from vtr.runtime.repeater import Repeater, StepRecord
    from vtr.runtime.route_script import load_route_script
    from vtr.runtime.teach import TeachConfig, teach
    from vtr.sim2d.server import ServerConfig, start_server_process

    say = _Say()
    model = find_model(cfg.model)
    # the policy as `vtr repeat` runs it by default: the current image recoloured to the subgoal's light first
    policy = LightMatchedPolicy(OnnxPolicy(model, threads=cfg.threads))
    h, w = policy.image_shape
    script = load_route_script(_route_path(cfg.route))
    say(f"model {model} ({w}x{h} images, horizon {policy.meta.horizon}); route '{script.name}'")

    from vtr.sim2d import CameraConfig, SimConfig

    sim_cfg = SimConfig(camera=CameraConfig(width=w, height=h), noise=cfg.noise)
    server = start_server_process(ServerConfig(bind="tcp://127.0.0.1:*", sim=sim_cfg))
    try:
        say(f"simulator server listening on {server.endpoint} (actuation noise {cfg.noise})")
        client = SimClient(server.endpoint, timeout_s=cfg.timeout_s, expect_shape=(h, w))
        try:
            route = teach(client, script, TeachConfig(dt=policy.meta.dt, seed=cfg.seed + 1))
            say(f"taught {len(route)} subgoals over {script.duration:.1f} s of driving")

            start = tuple(float(v) for v in route.poses[0])
            obs = client.reset(pose=start, seed=cfg.seed)
            poses: list[tuple[float, float, float]] = [obs.pose]
            commands: list[tuple[float, float]] = []

            def on_step(record: StepRecord) -> None:
                if record.commanded:
                    commands.append((record.v, record.w))
                    poses.append(pose_client.last_pose)

            pose_client = _PoseKeeper(client)
            summary = Repeater(pose_client, policy, route, on_step=on_step).run()
            if summary.status == "interrupted":  # the daemon stopped the robot on Ctrl-C; end the demo too
                raise KeyboardInterrupt
            say(
                f"repeated: {summary.status.value} after {summary.steps} steps, {summary.subgoals_reached}/"
                f"{summary.subgoals_total} subgoals"
            )
            ol_poses = _open_loop(client, script, start, cfg.seed, policy.meta.dt) if cfg.open_loop else None
            if ol_poses is not None:
                say("replayed the taught commands open loop (no camera) for comparison")
        finally:
            client.close()
    finally:
        server.terminate()
    say("simulator server stopped")
    # The taught route (megabytes of images) is not kept: `vtr teach --out` is the way to keep one.

    run_metrics = metrics.route_metrics(
        route.poses, np.asarray(poses), np.asarray(commands).reshape(-1, 2), summary.subgoals_reached
    )
    result: dict[str, Any] = {
        "model": str(model),
        "route": script.name,
        "noise": cfg.noise,
        "summary": summary.to_dict(),
        "velocitynet": run_metrics,
        "taught_poses": route.poses.tolist(),
        "repeated_poses": [list(p) for p in poses],
    }
    if ol_poses is not None:
        result["open_loop"] = metrics.route_metrics(
            route.poses, np.asarray(ol_poses), np.zeros((0, 2)), len(route)
        )
        result["open_loop_poses"] = [list(p) for p in ol_poses]
    print()
    print(format_table(result))
    png = cfg.out / f"{script.name}.png"
    try:
        write_png(result, png)
        result["png"] = str(png)
        print(f"\nplot: {png}")
    except ImportError:
        print("\n(no plot: matplotlib is not installed; pip install 'vtr-mpc[sim]')")
    say("done")
    return result


class _PoseKeeper:
    """The SimClient as the Repeater sees it: images only (the pose is stripped, so nothing in the repeat
    can steer by it); the true pose of the last frame is kept in ``last_pose`` for scoring."""

    def __init__(self, client: Any) -> None:
        self.client = client
        self.last_pose: tuple[float, float, float] | None = None

    def _strip(self, obs: Observation) -> Observation:
        self.last_pose = obs.pose
        return replace(obs, pose=None)  # the image, contact and range scan pass through

    def observe(self) -> Observation:
        return self._strip(self.client.observe())

    def step(self, v: float, w: float, duration: float) -> Observation:
        return self._strip(self.client.step(v, w, duration))

    def stop(self) -> None:
        self.client.stop()


def _open_loop(
    client: Any, script: Any, start: tuple[float, float, float], seed: int, dt: float
) -> list[Any]:
    obs = client.reset(pose=start, seed=seed)
    poses = [obs.pose]
    for seg in script.segments:
        for _ in range(max(1, round(seg.duration / dt))):
            poses.append(client.step(seg.v, seg.w, dt).pose)
    client.stop()
    return poses


def format_table(result: dict[str, Any]) -> str:
    """The paper's Table 1 column for this route beside ours (and open loop)."""
    from vtr.evaluation.scoring import PAPER

    vn = result["velocitynet"]
    ol = result.get("open_loop")
    paper = PAPER.get(result["route"])
    rotation = result["route"] == "rotation"
    key, unit = ("yaw_error_deg", "deg") if rotation else ("position_error_m", "m")
    s = result["summary"]
    cols = ["paper"] if paper else []
    cols += ["VelocityNet (ours)"] + (["open loop"] if ol else [])
    width = 20
    lines = [
        f"Route '{result['route']}', actuation noise {result['noise']}: for each taught subgoal, the distance to the "
        "nearest repeated pose",
        "",
        f"{'':<22}" + "".join(f"{c:>{width}}" for c in cols),
    ]
    for stat, label in (
        ("min", "min"),
        ("max", "max"),
        ("mean", "MAE" if rotation else "mean"),
        ("std", "std"),
    ):
        row = f"{label + f' ({unit})':<22}"
        if paper:
            row += f"{_num(paper[stat]):>{width}}"
        row += f"{_num(vn[key][stat]):>{width}}"
        if ol:
            row += f"{_num(ol[key][stat]):>{width}}"
        lines.append(row)
    extra = [
        ("cross-track (m)", vn["mean_cross_track_error_m"], ol["mean_cross_track_error_m"] if ol else None),
        (
            "final error (m)",
            vn["final_pose_error"]["position_m"],
            ol["final_pose_error"]["position_m"] if ol else None,
        ),
    ]
    for label, ours, theirs in extra:
        row = f"{label:<22}" + (f"{'':>{width}}" if paper else "") + f"{_num(ours):>{width}}"
        if ol:
            row += f"{_num(theirs):>{width}}"
        lines.append(row)
    lat = s.get("mean_latency_ms", {})
    lines += [
        "",
        f"completed: {'yes' if s['completed'] else 'no (' + s['status'] + ')'}  |  subgoals "
        f"{s['subgoals_reached']}/{s['subgoals_total']}  |  {s['steps']} control steps, {s['sim_time_s']:.1f} s "
        f"simulated, {s['wall_time_s']:.1f} s wall",
    ]
    if lat:
        parts = [f"{k} {v:.2f}" for k, v in lat.items() if k in ("inference", "preprocess", "error", "total")]
        lines.append("mean per step (ms): " + ", ".join(parts))
    return "\n".join(lines)


def _num(x: float | None) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return f"{x:.2e}" if 0 < abs(x) < 1e-3 else f"{x:.4f}"


def write_png(result: dict[str, Any], path: Path) -> Path:
    """Taught subgoals and repeated positions, top-down, over the house's rooms."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from vtr.evaluation.plots import draw_house, frame_route

    path.parent.mkdir(parents=True, exist_ok=True)  # only now: a failed demo leaves no empty folder
    taught = np.asarray(result["taught_poses"])
    rep = np.asarray(result["repeated_poses"])
    fig, ax = plt.subplots(figsize=(6.5, 7))
    draw_house(ax)
    if "open_loop_poses" in result:
        ol = np.asarray(result["open_loop_poses"])
        ax.plot(
            ol[:, 0], ol[:, 1], "--", color="tab:gray", lw=1.2, label="open-loop replay (no camera)", zorder=5
        )
    ax.scatter(taught[:, 0], taught[:, 1], s=14, color="tab:blue", label="taught subgoals", zorder=3)
    ax.scatter(rep[:, 0], rep[:, 1], s=5, color="tab:red", label="repeated with VelocityNet", zorder=4)
    frame_route(ax, taught)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    mean = result["velocitynet"]["position_error_m"]["mean"]
    ax.set_title(f"{result['route']}: taught vs repeated (mean error {mean * 1000:.1f} mm)")
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=2, frameon=False)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_arguments(parser, DemoConfig)


def run_cli(args: argparse.Namespace) -> int:
    result = run(config_from_args(DemoConfig, args))
    return 0 if result["summary"]["completed"] else 1  # a repeat that did not finish is a failed demo
