"""Simulator throughput: steps per second, one step = physics of one control step + render of one frame.

    vtr bench sim [--steps 2000] [--json out.json]

Single thread: `_limit_threads` sets the BLAS thread variables (read only by a BLAS not loaded yet).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import time
from dataclasses import asdict, dataclass

from vtr.runtime.atomic import write_text_atomic
from vtr.runtime.cliargs import add_config_arguments, config_from_args, opt
from vtr.runtime.contracts import CAMERA, CONTROL_DT


@dataclass(frozen=True)
class SimBenchConfig:
    """What the simulator throughput benchmark runs."""

    steps: int = opt(2000, "timed steps (after the warm-up)")
    warmup: int = opt(50, "untimed steps first (caches, allocator)")
    width: int = opt(CAMERA.width, "camera width in pixels")
    height: int = opt(CAMERA.height, "camera height in pixels")
    supersample: int = opt(1, "camera supersampling factor")
    fov: float = opt(CAMERA.fov_deg, "camera horizontal field of view in degrees")
    camera_height: float = opt(CAMERA.height_m, "camera height above the floor in metres")
    duration: float = opt(CONTROL_DT, "simulated seconds per step (the paper's control step)")
    house: str = opt("house", "map to benchmark")
    json_path: str | None = opt(None, "write the results as JSON here (atomically)", flag="--json")

    def __post_init__(self) -> None:
        for name in ("steps", "width", "height", "supersample"):
            if getattr(self, name) < 1:
                raise ValueError(f"SimBenchConfig.{name} must be >= 1, got {getattr(self, name)!r}")
        if self.warmup < 0:
            raise ValueError(f"SimBenchConfig.warmup must be >= 0, got {self.warmup!r}")
        if not (math.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"SimBenchConfig.duration must be > 0, got {self.duration!r}")


def _limit_threads() -> None:
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")


def _route_commands(duration: float) -> list[tuple[object, list[tuple[float, float, float]]]]:
    """Every shipped route as (start pose, [(v, w, duration), ...]): a drive through all rooms without collisions."""
    from vtr.sim2d.routes import list_routes, load_route

    out = []
    for name in list_routes():
        route = load_route(name)
        out.append((route.start, route.commands(duration)))
    return out


def run(cfg: SimBenchConfig) -> dict:
    """Measure and return {steps_per_s, render_ms_median, physics_ms_median, ...}.

    The robot drives the shipped routes one after the other (resetting at each route's start, which is
    not timed), so every room and distance to the walls is exercised. Each timed step is
    Simulator.advance (physics) then Simulator.observe (render), timed separately in the same loop.
    """
    import numpy as np

    from vtr.sim2d.config import CameraConfig, SimConfig
    from vtr.sim2d.simulator import Simulator

    sim = Simulator(
        SimConfig(
            house=cfg.house,
            camera=CameraConfig(
                width=cfg.width,
                height=cfg.height,
                supersample=cfg.supersample,
                fov_deg=cfg.fov,
                camera_height=cfg.camera_height,
            ),
        )
    )
    routes = _route_commands(cfg.duration)

    def drive(n: int) -> tuple[list[float], list[float]]:
        physics, render = [], []
        done = 0
        clock = time.perf_counter
        while done < n:
            for start, commands in routes:
                sim.reset(pose=start, seed=0)
                for v, w, d in commands:
                    t0 = clock()
                    sim.advance(v, w, d)
                    t1 = clock()
                    sim.observe()
                    t2 = clock()
                    physics.append(t1 - t0)
                    render.append(t2 - t1)
                    done += 1
                    if done >= n:
                        return physics, render
        return physics, render

    drive(cfg.warmup)
    physics, render = drive(cfg.steps)
    # The raycast alone (the rest of a render is per-pixel work), over poses along the first routes.
    raycast = []
    for start, commands in routes:
        sim.reset(pose=start, seed=0)
        for v, w, d in commands:
            sim.advance(v, w, d)
            p = sim.pose
            t0 = time.perf_counter()
            sim.camera.raycast(p.x, p.y, p.yaw)
            raycast.append(time.perf_counter() - t0)
        if len(raycast) >= min(cfg.steps, 1000):
            break
    total = float(np.sum(physics) + np.sum(render))
    per_step = np.asarray(physics) + np.asarray(render)
    result = {
        "benchmark": "sim_throughput",
        "config": asdict(cfg),
        "steps_per_s": cfg.steps / total,
        # Robust to other processes on a shared machine: the typical step, not the average with preemptions.
        "steps_per_s_from_median": 1.0 / float(np.median(per_step)),
        "step_ms_mean": 1e3 * total / cfg.steps,
        "step_ms_median": 1e3 * float(np.median(per_step)),
        "render_ms_median": 1e3 * statistics.median(render),
        "render_ms_mean": 1e3 * statistics.fmean(render),
        "raycast_ms_median": 1e3 * statistics.median(raycast),
        "physics_ms_median": 1e3 * statistics.median(physics),
        "physics_ms_mean": 1e3 * statistics.fmean(physics),
        "physics_substeps_per_step": math.ceil(cfg.duration / sim.cfg.physics_dt - 1e-9),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "machine": platform.machine(),
        "target_steps_per_s": 1500,
    }
    if cfg.json_path:
        write_text_atomic(cfg.json_path, json.dumps(result, indent=2) + "\n")
    return result


def format_table(r: dict) -> str:
    c = r["config"]
    rows = [
        ("frame", f"{c['width']}x{c['height']} x{c['supersample']} supersample"),
        ("camera", f"{c.get('fov', 90):g} deg at {c.get('camera_height', 0.3):g} m"),
        ("steps/s (physics + render)", f"{r['steps_per_s']:.0f}  (target {r['target_steps_per_s']})"),
        ("steps/s from the median step", f"{r['steps_per_s_from_median']:.0f}"),
        ("step ms median / mean", f"{r['step_ms_median']:.3f} / {r['step_ms_mean']:.3f}"),
        ("render ms median / mean", f"{r['render_ms_median']:.3f} / {r['render_ms_mean']:.3f}"),
        ("  of which raycast, ms median", f"{r['raycast_ms_median']:.3f}"),
        (
            f"physics ms median / mean ({r['physics_substeps_per_step']} substeps)",
            f"{r['physics_ms_median']:.3f} / {r['physics_ms_mean']:.3f}",
        ),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_arguments(parser, SimBenchConfig)


def run_cli(args: argparse.Namespace) -> int:
    _limit_threads()
    cfg = config_from_args(SimBenchConfig, args)
    print(format_table(run(cfg)))
    return 0
