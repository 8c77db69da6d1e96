"""`vtr eval`: closed-loop tracking on scripted routes, scored the paper's way, beside baselines.

For every route (``sim2d/routes/*.json``): teach it once (noise-free, in process, over
``sim2d.local_robot.LocalRobot``), then repeat it in two scenarios:

* ``noise``  - from the taught start pose with actuation noise on (``--noise``, the simulator's level);
* ``offset`` - from a start pose shifted by ``--offset`` (dx, dy in the robot's frame, dyaw), noise off.

Each scenario runs every method: VelocityNet (the shipped ONNX through the runtime's controller), its int8
twin and a w2 = 0 ablation when given, open-loop replay of the taught commands, and an online MPC that
searches velocities with ViewNet at every step (the paper's future work). The runtime sees only images;
poses are read from the simulator for scoring only.

Outputs: a JSON file with every number (per route, per scenario, per method, and aggregated), a Markdown
table beside the paper's Tables 1 and 2, and PNG plots in the paper's style.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vtr.benchmarks.results import write_json
from vtr.evaluation.mpc import ViewNetMPC
from vtr.evaluation.plots import write_plots
from vtr.evaluation.runs import PoseOracle, repeat_closed_loop, repeat_open_loop
from vtr.evaluation.scoring import PAPER, PAPER_ROUTES, aggregate, bar_checks, score
from vtr.evaluation.tables import markdown_report
from vtr.models import find_int8, find_model
from vtr.runtime.atomic import write_text_atomic
from vtr.runtime.cliargs import add_config_arguments, config_from_args, opt
from vtr.runtime.contracts import CONTROL_DT, Policy
from vtr.runtime.route_script import RouteScript, load_route_script
from vtr.runtime.status_line import Progress
from vtr.sim2d.routes import ROUTES_DIR
from vtr.training.pool import process_pool

QUICK_ROUTES = ("translation",)


@dataclass
class EvalConfig:
    """Settings of one closed-loop evaluation."""

    model: Path | None = opt(None, "fp32 VelocityNet ONNX (default: the shipped models/velocitynet.onnx)")
    routes: tuple[str, ...] = opt(
        (), "route names (stems in sim2d/routes) or ROUTE.json paths (default: all)"
    )
    noise: float = opt(0.05, "actuation noise level of the repeat runs (SimConfig.noise)")
    offset: tuple[float, float, float] = opt(
        (0.03, 0.03, 3.0),
        "start offset of the offset scenario: dx, dy (m, robot frame), dyaw (deg)",
        metavar=("DX", "DY", "DYAW"),
    )
    int8_model: Path | None = opt(
        None, "int8 twin (default: <model stem>-int8.onnx beside the model, if present)"
    )
    ablation_model: Path | None = opt(None, "a VelocityNet trained with w2 = 0 (ONNX)")
    viewnet: Path | None = opt(None, "ViewNet checkpoint: enables the online-MPC baseline")
    mpc_routes: tuple[str, ...] = opt(
        PAPER_ROUTES, "routes the (slow) online MPC runs on, noise scenario only"
    )
    mpc_samples: int = opt(32, "candidate (v, w) sequences per MPC step")
    mpc_iterations: int = 2  # cross-entropy refinements of the candidate distribution
    open_loop: bool = opt(True, "run the open-loop replay baseline")
    oracle: bool = opt(False, "add the pose-oracle diagnostic (true poses: the floor e_m switching leaves)")
    e_m: float | None = opt(None, "fixed switch threshold (paper: 17); default: calibrated per route")
    dt: float = CONTROL_DT  # s each command is applied for (the paper's control step)
    max_steps_factor: float = 8.0  # give up after factor * subgoals + 50 control steps
    seed: int = opt(0, "actuation noise seed")
    threads: int = opt(1, "onnxruntime / torch threads per worker")
    workers: int = opt(2, "processes over routes (1 with --quick)")
    quick: bool = opt(False, "one short route, noise scenario only, no MPC")
    json_path: Path | None = opt(None, "write every number here (and a .md table beside it)", flag="--json")
    plots_dir: Path | None = opt(None, "folder for the PNG plots", flag="--plots")
    markdown_path: Path | None = None  # default: beside the JSON file, same stem + .md

    def __post_init__(self) -> None:
        self.model = find_model(self.model)
        if self.quick:
            self.workers = 1
        if not 0.0 <= self.noise <= 1.0:
            raise ValueError(f"noise must be in [0, 1], got {self.noise}")
        if len(self.offset) != 3 or not all(math.isfinite(o) for o in self.offset):
            raise ValueError(f"offset must be three finite numbers (dx m, dy m, dyaw deg), got {self.offset}")
        for name in ("ablation_model", "viewnet"):
            value = getattr(self, name)
            if value is not None and Path(value).is_dir():
                raise ValueError(f"--{name.replace('_', '-')} {value} is a folder, not a model file")
            if value is not None and not Path(value).is_file():
                raise ValueError(f"{name} not found: {value}")
        self.int8_model = find_int8(self.model, self.int8_model)
        if self.mpc_samples < 2 or self.mpc_iterations < 1:
            raise ValueError(
                f"mpc_samples must be >= 2 and mpc_iterations >= 1, got {self.mpc_samples}, "
                f"{self.mpc_iterations}"
            )
        if self.e_m is not None and not self.e_m > 0:
            raise ValueError(f"e_m must be positive, got {self.e_m}")
        if not self.dt > 0 or not self.max_steps_factor > 0:
            raise ValueError(
                f"dt and max_steps_factor must be positive, got {self.dt}, {self.max_steps_factor}"
            )
        if self.threads < 1 or self.workers < 1:
            raise ValueError(f"threads and workers must be >= 1, got {self.threads}, {self.workers}")
        if self.json_path is not None and self.markdown_path is None:
            self.markdown_path = Path(self.json_path).with_suffix(".md")
        for path in route_files(self.routes):  # a bad route is an input error now, not in a worker later
            load_route_script(path)


# ---------------------------------------------------------------- routes and teach


def route_files(names: tuple[str, ...]) -> list[Path]:
    """ROUTE.json paths for names (stems in sim2d/routes) or paths; all routes when names is empty."""
    if not names:
        files = sorted(ROUTES_DIR.glob("*.json"))
        if not files:
            raise ValueError(f"no routes in {ROUTES_DIR}")
        # The paper's scenarios first, in the paper's order.
        return sorted(
            files,
            key=lambda p: (
                p.stem not in PAPER_ROUTES,
                PAPER_ROUTES.index(p.stem) if p.stem in PAPER_ROUTES else 0,
                p.stem,
            ),
        )
    out = []
    for name in names:
        path = Path(name)
        if not path.suffix:
            path = ROUTES_DIR / f"{name}.json"
        if not path.is_file():
            raise ValueError(
                f"route not found: {name} (looked at {path}); name one of "
                f"{', '.join(p.stem for p in sorted(ROUTES_DIR.glob('*.json')))} or a ROUTE.json file"
            )
        out.append(path)
    return out


def make_robot(
    noise: float,
    image_size: tuple[int, int],
    house: str = "house",
    scan: bool = False,
    camera: tuple[float, float] | None = None,
    sensor: Any = None,
) -> Any:
    """An in-process simulated robot; ``scan`` adds the range scanner's reading to every observation;
    ``camera``: (field of view deg, height m), None for the default camera; ``sensor``: a
    sim2d.sensor.SensorConfig applied to every frame (None: the ideal camera)."""
    from vtr.sim2d import SimConfig, Simulator
    from vtr.sim2d.config import camera_config
    from vtr.sim2d.local_robot import LocalRobot

    h, w = image_size
    sim = Simulator(SimConfig(camera=camera_config(w, h, camera), sensor=sensor, noise=noise, house=house))
    return LocalRobot(sim, scan=scan)


def teach(
    script: Path | RouteScript,
    image_size: tuple[int, int],
    dt: float,
    house: str = "house",
    camera: tuple[float, float] | None = None,
    sensor: Any = None,
) -> tuple[Any, Any]:
    """Drive the scripted route (a ROUTE.json path or a RouteScript) noise-free in ``house`` with
    `runtime.teach` (``camera``: (fov deg, height m), None: the default; ``sensor``: the camera's sensor
    realism, as the robot's own camera has it at teach time too); returns (Route, RouteScript)."""
    from vtr.runtime.teach import TeachConfig
    from vtr.runtime.teach import teach as teach_route

    if not isinstance(script, RouteScript):
        script = load_route_script(script)
    # the route keeps the free distance its scan saw
    robot = make_robot(0.0, image_size, house, scan=True, camera=camera, sensor=sensor)
    return teach_route(robot, script, TeachConfig(dt=dt, seed=0)), script


# ---------------------------------------------------------------- one route, all methods


def _offset_start(
    start: tuple[float, float, float], offset: tuple[float, float, float]
) -> tuple[float, float, float]:
    x, y, yaw = start
    dx, dy, dyaw_deg = offset
    c, s = math.cos(yaw), math.sin(yaw)
    return (x + c * dx - s * dy, y + s * dx + c * dy, yaw + math.radians(dyaw_deg))


def evaluate_route(script_path: Path, cfg: EvalConfig) -> dict[str, Any]:
    """Teach one route, then run every scenario and method on it (a process-pool task)."""
    os.environ.setdefault("OMP_NUM_THREADS", str(cfg.threads))
    from vtr.runtime.policy import OnnxPolicy

    t_start = time.perf_counter()
    fp32 = OnnxPolicy(cfg.model, threads=cfg.threads)
    image_size = fp32.image_shape
    route, script = teach(script_path, image_size, cfg.dt)
    start = tuple(float(v) for v in route.poses[0])
    methods: dict[str, Policy | None] = {"velocitynet": fp32}
    if cfg.int8_model is not None:
        methods["velocitynet_int8"] = OnnxPolicy(cfg.int8_model, threads=cfg.threads)
    if cfg.ablation_model is not None:
        methods["ablation_w2_0"] = OnnxPolicy(cfg.ablation_model, threads=cfg.threads)
    if cfg.viewnet is not None and not cfg.quick and script_path.stem in cfg.mpc_routes:
        mpc = ViewNetMPC(
            cfg.viewnet, fp32.meta.horizon, cfg.mpc_samples, cfg.mpc_iterations, cfg.threads, cfg.seed
        )
        methods["online_mpc"] = mpc
    if cfg.oracle:
        meta = fp32.meta
        methods["pose_oracle"] = PoseOracle(meta.v_max, meta.w_max, meta.horizon, cfg.dt, image_size)
    if cfg.open_loop:
        methods["open_loop"] = None

    scenarios = {"noise": (start, cfg.noise)}
    if not cfg.quick:
        scenarios["offset"] = (_offset_start(start, cfg.offset), 0.0)
    results: dict[str, Any] = {}
    for scen, (pose, noise) in scenarios.items():
        results[scen] = {}
        for name, policy in methods.items():
            if name in ("online_mpc", "pose_oracle") and scen != "noise":
                continue
            robot = make_robot(noise, image_size)
            if policy is None:
                log = repeat_open_loop(robot, script, pose, cfg.seed, cfg.dt)
            else:
                log = repeat_closed_loop(robot, policy, route, pose, cfg, cfg.seed)
            results[scen][name] = score(route, log, open_loop=policy is None)
    return {
        "name": script_path.stem,
        "file": str(script_path),
        "paper_scenario": script_path.stem in PAPER_ROUTES,
        "subgoals": len(route),
        "taught_poses": np.round(route.poses, 5).tolist(),
        "start": list(start),
        "scenarios": results,
        "wall_s": time.perf_counter() - t_start,
    }


# ---------------------------------------------------------------- entry points


def run(cfg: EvalConfig) -> dict[str, Any]:
    """Evaluate every route (in a process pool when workers > 1) and write JSON, Markdown and plots."""
    names = cfg.routes or (QUICK_ROUTES if cfg.quick else ())
    files = route_files(names)
    t0 = time.perf_counter()
    with Progress("vtr eval", len(files)) as progress:  # a live line on stderr, on a terminal only
        if cfg.workers > 1 and len(files) > 1:
            with process_pool(min(cfg.workers, len(files))) as ex:  # Ctrl-C stops it at once
                futures = {ex.submit(evaluate_route, f, cfg): f for f in files}
                for done in progress.as_completed(futures):
                    progress.advance(futures[done].stem)
                routes = [f.result() for f in futures]
        else:
            routes = []
            for f in files:
                progress.start(f.stem)
                routes.append(evaluate_route(f, cfg))
                progress.advance(f.stem)
    agg = aggregate(routes)
    notes = []
    if cfg.int8_model is None:
        notes.append("int8 (no <model>-int8.onnx beside the model; pass --int8-model)")
    if cfg.ablation_model is None:
        notes.append("w2 = 0 ablation (pass --ablation-model)")
    if cfg.viewnet is None:
        notes.append("online MPC (pass --viewnet with a ViewNet checkpoint)")
    elif cfg.quick:
        notes.append("online MPC (skipped in --quick)")
    result: dict[str, Any] = {
        "notes": notes,
        "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()},
        "paper": PAPER,
        "routes": routes,
        "aggregate": agg,
        "bar": bar_checks(routes, agg),
        "wall_s": time.perf_counter() - t0,
    }
    if cfg.plots_dir is not None:
        result["plots"] = [str(p) for p in write_plots(result, Path(cfg.plots_dir))]
    if cfg.json_path is not None:
        write_json(Path(cfg.json_path), result)
    if cfg.markdown_path is not None:
        write_text_atomic(cfg.markdown_path, markdown_report(result))
    return result


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from vtr.evaluation import condition_suite, house_suite, realtime_pace

    add_config_arguments(parser, EvalConfig)
    parser.add_argument("--run", type=Path, default=None, help="score a run recorded by `vtr repeat --mcap`")
    parser.add_argument(
        "--taught", type=Path, default=None, help="--run: the taught route (.npz) it repeated"
    )

    condition_suite.add_arguments(parser)
    realtime_pace.add_arguments(parser)
    house_suite.add_arguments(parser)


def run_cli(args: argparse.Namespace) -> int:
    if getattr(args, "houses", None) is not None:  # generated routes in procedural houses
        from vtr.evaluation import house_suite

        return house_suite.run_cli(args)
    if getattr(args, "suite", None) == "pace":  # on a wall-clock robot
        from vtr.evaluation import realtime_pace

        return realtime_pace.run_cli(args)
    if getattr(args, "suite", None) == "conditions":
        from vtr.evaluation import condition_suite

        return condition_suite.run_cli(args)
    if args.run is not None:  # a run recorded on any robot instead of simulated runs
        from vtr.evaluation.recorded_runs import run_cli as score_recorded_cli

        return score_recorded_cli(args)
    cfg = config_from_args(EvalConfig, args)  # a ValueError is one line, exit 2 (runtime.commands)
    result = run(cfg)
    print(markdown_report(result))
    for path in (cfg.json_path, cfg.markdown_path, cfg.plots_dir):
        if path is not None:
            print(f"wrote {path}")
    return 0
