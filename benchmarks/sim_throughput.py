"""Simulator throughput: steps per second, one step = physics of one control step + render of one frame.

    python -m benchmarks.sim_throughput [--steps 2000] [--json out.json]   (wired as `vtr bench sim`)

Single thread: BLAS is limited to one thread before numpy loads when run from the command line.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path


@dataclass(frozen=True)
class SimBenchConfig:
    """What the simulator throughput benchmark runs."""

    steps: int = 2000
    """Timed steps (after warm-up)."""
    warmup: int = 50
    """Untimed steps first (caches, allocator)."""
    width: int = 128
    """Camera width (pixels)."""
    height: int = 128
    """Camera height (pixels)."""
    supersample: int = 1
    """Camera supersampling factor."""
    duration: float = 0.1
    """Simulated seconds per step (the paper's control step)."""
    house: str = "house"
    """Map to benchmark."""
    json_path: str | None = None
    """Write the results as JSON here (atomically)."""

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


def run(cfg: SimBenchConfig) -> dict:
    """Measure and return {steps_per_s, render_ms_median, physics_ms_median, ...}."""
    import numpy as np

    from sim2d.config import CameraConfig, SimConfig
    from sim2d.physics import advance
    from sim2d.simulator import Simulator

    sim = Simulator(
        SimConfig(
            house=cfg.house,
            camera=CameraConfig(width=cfg.width, height=cfg.height, supersample=cfg.supersample),
        )
    )
    sim.reset(seed=0)
    rng = np.random.default_rng(0)
    # A random walk that stays near the start: random commands, reset when it bumps into something.
    cmds = [(float(rng.uniform(-0.2, 0.5)), float(rng.uniform(-1, 1))) for _ in range(cfg.steps + cfg.warmup)]
    for v, w in cmds[: cfg.warmup]:
        sim.step(v, w, cfg.duration)

    t0 = time.perf_counter()
    for v, w in cmds[cfg.warmup :]:
        sim.step(v, w, cfg.duration)
        if sim.collided:
            sim.reset(seed=0)
    total = time.perf_counter() - t0

    poses = []
    sim.reset(seed=0)
    for v, w in cmds[: min(cfg.steps, 500)]:
        sim.step(v, w, cfg.duration)
        poses.append(sim.pose)
    render_times = []
    for p in poses:
        t = time.perf_counter()
        sim.camera.render(p.x, p.y, p.yaw)
        render_times.append(time.perf_counter() - t)
    physics_times = []
    world = sim._require().world
    for v, w in cmds[: min(cfg.steps, 500)]:
        t = time.perf_counter()
        advance(world, v, w * 0.1, cfg.duration, sim.cfg.physics_dt)
        physics_times.append(time.perf_counter() - t)

    result = {
        "benchmark": "sim_throughput",
        "config": asdict(cfg),
        "steps_per_s": cfg.steps / total,
        "step_ms_mean": 1e3 * total / cfg.steps,
        "render_ms_median": 1e3 * statistics.median(render_times),
        "physics_ms_median": 1e3 * statistics.median(physics_times),
        "physics_substeps_per_step": math.ceil(cfg.duration / sim.cfg.physics_dt - 1e-9),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "machine": platform.machine(),
        "target_steps_per_s": 1500,
    }
    if cfg.json_path:
        path = Path(cfg.json_path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(result, indent=2) + "\n")
        os.replace(tmp, path)
    return result


def format_table(r: dict) -> str:
    c = r["config"]
    rows = [
        ("frame", f"{c['width']}x{c['height']} x{c['supersample']} supersample"),
        ("steps/s (physics + render)", f"{r['steps_per_s']:.0f}  (target {r['target_steps_per_s']})"),
        ("mean ms per step", f"{r['step_ms_mean']:.3f}"),
        ("median ms per render", f"{r['render_ms_median']:.3f}"),
        (f"median ms physics ({r['physics_substeps_per_step']} substeps)", f"{r['physics_ms_median']:.3f}"),
    ]
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--steps", type=int, default=2000, help="timed steps (default 2000)")
    parser.add_argument("--warmup", type=int, default=50, help="untimed warm-up steps")
    parser.add_argument("--width", type=int, default=128)
    parser.add_argument("--height", type=int, default=128)
    parser.add_argument("--supersample", type=int, default=1)
    parser.add_argument("--duration", type=float, default=0.1, help="simulated seconds per step")
    parser.add_argument("--house", default="house")
    parser.add_argument(
        "--json", dest="json_path", default=None, metavar="FILE", help="write results as JSON"
    )


def run_cli(args: argparse.Namespace) -> int:
    _limit_threads()
    cfg = SimBenchConfig(
        steps=args.steps,
        warmup=args.warmup,
        width=args.width,
        height=args.height,
        supersample=args.supersample,
        duration=args.duration,
        house=args.house,
        json_path=args.json_path,
    )
    print(format_table(run(cfg)))
    return 0


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(p)
    sys.exit(run_cli(p.parse_args()))
