"""`vtr eval --houses A:B`: teach and repeat generated routes in procedural houses (random:SEED).

For each house and route index k < ``routes_per_house``, sim2d.route_gen makes the route a user would teach
there (route seed k); it is taught once noise-free (evaluation.harness.teach), then repeated with actuation
noise ``noise`` under each seed, by the runtime's default repeat (the condition suite's ``after`` method:
evaluation.condition_run.run_once over evaluation.runs, the Repeater). A run counts as completed only when
the repeat finished and the robot touched nothing. Reported per house and overall (house_tables): completion,
the paper's mean nearest-point error over completed runs, and control steps per taught step.

Held-out discipline: random:5000..5099 are reserved for final tables; develop on random:900..999.
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vtr.evaluation.condition_run import CONTROLLERS, step_compute_summary
from vtr.evaluation.metrics import off_path
from vtr.runtime.status_line import Progress

MAX_HOUSES = 1000


def parse_camera(spec: str) -> tuple[float, float]:
    """``"FOV,HEIGHT"`` -> (fov deg, height m), checked as sim2d.CameraConfig checks them."""
    from vtr.sim2d.config import camera_config

    try:
        fov, height = (float(v) for v in spec.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected FOV,HEIGHT (degrees, metres), got {spec!r}") from None
    try:
        camera_config(128, 128, (fov, height))
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None
    return fov, height


def parse_houses(spec: str) -> tuple[str, ...]:
    """House names from ``A:B`` (random:A .. random:B-1, as a Python range) or a comma list whose items are
    seeds (``A``: random:A) or map names/paths (``house``: the paper-style map); ValueError otherwise."""
    from vtr.sim2d.house import RANDOM_PREFIX, resolve_house_path
    from vtr.sim2d.procedural import MAX_SEED

    text = spec.strip()
    try:
        if ":" in text and "," not in text and not text.startswith(RANDOM_PREFIX):
            a, b = (int(p) for p in text.split(":"))
            items = [str(s) for s in range(a, b)]
        else:
            items = [p.strip() for p in text.split(",")]
    except ValueError:
        raise ValueError(
            f"--houses {spec!r}: expected A:B (seeds A..B-1) or a list of seeds or map names"
        ) from None
    names = []
    for item in items:
        seed = item[len(RANDOM_PREFIX) :] if item.startswith(RANDOM_PREFIX) else item
        if seed.isdigit() and int(seed) <= MAX_SEED:
            names.append(f"{RANDOM_PREFIX}{int(seed)}")
        elif item and not item.startswith(("-", RANDOM_PREFIX)) and not item.isdigit():
            try:  # an unknown map is a one-line error now, not in a worker later
                resolve_house_path(item)
            except ValueError as err:
                raise ValueError(f"--houses {spec!r}: {err}") from None
            names.append(item)
        else:
            raise ValueError(f"--houses {spec!r}: {item!r} is neither a seed in 0..{MAX_SEED} nor a map name")
    if not names or len(names) > MAX_HOUSES:
        raise ValueError(f"--houses {spec!r}: give 1..{MAX_HOUSES} houses")
    if len(set(names)) != len(names):
        raise ValueError(f"--houses {spec!r}: a house is named twice")
    return tuple(names)


@dataclass
class HouseSuiteConfig:
    """One held-out-house evaluation."""

    houses: tuple[str, ...]  # house names: random:SEED (or any map sim2d.house loads)
    routes_per_house: int = 3
    noise: float = 0.05
    seeds: tuple[int, ...] = (0, 1, 2)
    model: Path | None = None  # fp32 VelocityNet ONNX; None: the shipped one (vtr.models.find_model)
    controller: str = "after"  # the runtime's default repeat
    oracle: bool = False  # also repeat with the pose oracle (evaluation.runs.PoseOracle): switching's floor
    max_steps_factor: float = 8.0  # step limit = factor * subgoals + 50
    dt: float = 0.1
    camera: tuple[float, float] | None = None  # (fov deg, height m) of teach and repeat; None: the default
    threads: int = 1
    workers: int = 2
    json_path: Path | None = None
    plot_path: Path | None = None  # default: beside the JSON file, same stem + .png

    def __post_init__(self) -> None:
        from vtr.models import find_model

        try:
            self.model = find_model(self.model)
        except FileNotFoundError as err:
            raise ValueError(str(err)) from err
        if not 1 <= self.routes_per_house <= 100:
            raise ValueError(f"--routes-per-house must be in 1..100, got {self.routes_per_house}")
        if not 0.0 <= self.noise <= 1.0:
            raise ValueError(f"--noise must be in [0, 1], got {self.noise}")
        if not self.seeds or len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"--seeds: give one or more distinct seeds, got {list(self.seeds)}")
        if self.controller not in CONTROLLERS:
            raise ValueError(f"unknown controller {self.controller!r}; known: {', '.join(CONTROLLERS)}")
        if not self.max_steps_factor > 0 or self.workers < 1 or self.threads < 1:
            raise ValueError("max_steps_factor must be > 0, workers and threads >= 1")
        if self.json_path is not None and self.plot_path is None:
            self.plot_path = Path(self.json_path).with_suffix(".png")


# ---------------------------------------------------------------------------------------------- runs


def evaluate_route(task: tuple[str, int, HouseSuiteConfig]) -> dict[str, Any]:
    """Generate, teach and repeat (every seed) route ``k`` of ``house``: a process-pool task."""
    from vtr.evaluation.condition_run import Condition, cached_policy, run_once
    from vtr.evaluation.harness import teach
    from vtr.evaluation.runs import PoseOracle
    from vtr.sim2d.house import HouseError, load_house
    from vtr.sim2d.route_gen import generate_route, route_json

    house, k, cfg = task
    os.environ.setdefault("OMP_NUM_THREADS", str(cfg.threads))
    t0 = time.perf_counter()
    out: dict[str, Any] = {"house": house, "route_seed": k, "runs": []}
    try:
        script = generate_route(house, k)
    except (
        RuntimeError,
        HouseError,
    ) as err:  # no valid route, or a house that cannot be built: say so, go on
        return {**out, "error": str(err), "wall_s": time.perf_counter() - t0}
    policy = cached_policy(Path(cfg.model), cfg.threads)
    route, _ = teach(script, tuple(policy.image_shape), cfg.dt, house, camera=cfg.camera)
    h = load_house(house)
    xy = route.poses[:, :2]
    out.update(
        route=route_json(script),
        subgoals=len(route),
        duration_s=script.duration,
        length_m=float(np.sum(np.hypot(*np.diff(xy, axis=0).T))),
        rooms=len({h.room_at(float(x), float(y)) for x, y in xy}),
        taught_path=np.round(xy, 3).tolist(),
    )
    methods = [("velocitynet", policy, CONTROLLERS[cfg.controller])]
    if cfg.oracle:  # true poses steer, the images still switch subgoals; unwrapped, so no light matching
        meta = policy.meta
        oracle = PoseOracle(meta.v_max, meta.w_max, meta.horizon, cfg.dt, tuple(policy.image_shape))
        methods.append(("pose_oracle", oracle, CONTROLLERS["after_no_light_matching"]))
    condition = Condition(noise=cfg.noise, camera=cfg.camera)
    for name, pol, method in methods:
        for s in cfg.seeds:
            run = run_once(route, script, condition, house, s, method, pol, cfg, keep_path=True)
            out["runs"].append({"method": name, "seed": s, **run})
    out["wall_s"] = time.perf_counter() - t0
    return out


def summarise(routes: list[dict[str, Any]], houses: tuple[str, ...]) -> dict[str, Any]:
    """Per house and overall: completion (x/N), mean and median of the runs' mean nearest-point errors and the
    largest subgoal error (mm, completed runs), steps per taught step (completed runs), contacts and failure
    causes."""
    from collections import Counter

    def stats(rs: list[dict[str, Any]], method: str = "velocitynet") -> dict[str, Any]:
        runs = [r for route in rs for r in route["runs"] if r.get("method", "velocitynet") == method]
        done = [r for r in runs if r["completed"]]
        causes = Counter(r["cause"].split(":")[0] for r in runs if not r["completed"])
        return {
            "routes": len(rs),
            "routes_not_generated": sum("error" in r for r in rs),
            "runs": len(runs),
            "completed": len(done),
            "completed_off_path": off_path(done),
            "completion": len(done) / len(runs) if runs else None,
            "mean_error_mm": 1000 * float(np.mean([r["position_error_m"] for r in done])) if done else None,
            "median_error_mm": 1000 * float(np.median([r["position_error_m"] for r in done]))
            if done
            else None,
            "max_error_mm": 1000 * float(np.max([r["max_position_error_m"] for r in done])) if done else None,
            "steps_per_taught_step": float(np.mean([r["steps_per_taught_step"] for r in done]))
            if done
            else None,
            "runs_with_contact": sum(r.get("contacts", 0) > 0 for r in runs),
            "failure_causes": dict(causes),
        }

    out = {
        "per_house": {h: stats([r for r in routes if r["house"] == h]) for h in houses},
        "overall": stats(routes),
    }
    if any(r.get("method") == "pose_oracle" for route in routes for r in route["runs"]):
        out["pose_oracle"] = {
            "per_house": {h: stats([r for r in routes if r["house"] == h], "pose_oracle") for h in houses},
            "overall": stats(routes, "pose_oracle"),
        }
    return out


def _completed(routes: list[dict[str, Any]]) -> str:
    runs = [r for route in routes for r in route["runs"] if r["method"] == "velocitynet"]
    return f"{sum(r['completed'] for r in runs)}/{len(runs)} runs completed"


def _result(cfg: HouseSuiteConfig, routes: list[dict[str, Any]], total: int, t0: float) -> dict[str, Any]:
    routes = sorted(routes, key=lambda r: (cfg.houses.index(r["house"]), r["route_seed"]))
    out = {
        "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()},
        "summary": summarise(routes, cfg.houses),
        "step_compute": step_compute_summary(
            [r for route in routes for r in route.get("runs", []) if r.get("method") != "pose_oracle"]
        ),
        "routes": routes,
        "wall_s": time.perf_counter() - t0,
    }
    if len(routes) < total:
        out["partial"] = f"{len(routes)} of {total} routes finished"
    return out


def _write(cfg: HouseSuiteConfig, result: dict[str, Any]) -> None:
    import json

    from vtr.evaluation.house_tables import markdown
    from vtr.runtime.atomic import write_text_atomic

    assert cfg.json_path is not None
    write_text_atomic(cfg.json_path, json.dumps(result, separators=(",", ":")))  # paths: keep it compact
    write_text_atomic(Path(cfg.json_path).with_suffix(".md"), markdown(result))


def run(cfg: HouseSuiteConfig, progress: bool = True) -> dict[str, Any]:
    """Every (house, route) task, in a process pool when workers > 1; writes JSON, Markdown and a picture.

    The JSON and Markdown files are rewritten (atomically) after every finished route, marked partial, so
    an interrupted run keeps what it measured."""
    from vtr.evaluation.house_tables import write_picture

    tasks = [(h, k, cfg) for h in cfg.houses for k in range(cfg.routes_per_house)]
    t0 = time.perf_counter()
    routes: list[dict[str, Any]] = []
    line = Progress("houses (routes)", len(tasks), quiet=not progress)  # stderr, a terminal only

    def finished(route: dict[str, Any]) -> None:
        routes.append(route)
        line.advance(_completed(routes))
        if cfg.json_path is not None and len(routes) < len(tasks):
            _write(cfg, _result(cfg, routes, len(tasks), t0))

    with line:
        if cfg.workers > 1 and len(tasks) > 1:
            from vtr.training.pool import process_pool

            with process_pool(min(cfg.workers, len(tasks))) as ex:  # Ctrl-C stops it at once
                for fut in line.as_completed([ex.submit(evaluate_route, t) for t in tasks]):
                    finished(fut.result())
        else:
            for t in tasks:
                finished(evaluate_route(t))
    result = _result(cfg, routes, len(tasks), t0)
    if cfg.json_path is not None:
        _write(cfg, result)
    if cfg.plot_path is not None:
        result["plot"] = str(write_picture(result, Path(cfg.plot_path)))
    return result


# --------------------------------------------------------------------------- CLI (inside `vtr eval`)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of --houses, added to `vtr eval` (which owns --model, --noise, --seeds, --json, ...)."""
    g = parser.add_argument_group("held-out houses (--houses): generated routes in procedural houses")
    g.add_argument(
        "--houses",
        default=None,
        metavar="A:B",
        help="evaluate in procedural houses random:A .. random:B-1 (or a list A,B,house of seeds and "
        "map names) instead; uses --noise, --seeds, --model, --controllers (one), --oracle, --workers, "
        "--max-steps-factor; --json also writes .md and .png beside it (default: off; held-out houses are 5000..5099, tune on 900..999)",
    )
    g.add_argument(
        "--routes-per-house",
        type=int,
        default=3,
        help="generated routes per house, route seeds 0..N-1 (default: %(default)s)",
    )
    g.add_argument(
        "--camera",
        type=parse_camera,
        default=None,
        metavar="FOV,HEIGHT",
        help="teach and repeat with this camera: horizontal field of view (deg) and height above the floor (m), "
        "e.g. 65,0.3 (default: the shipped model's camera, 90,0.3)",
    )


def run_cli(args: argparse.Namespace) -> int:
    from vtr.evaluation.house_tables import markdown

    controllers = args.controllers or ["after"]
    if len(controllers) != 1:
        raise ValueError(f"--houses runs one controller; got --controllers {' '.join(controllers)}")
    cfg = HouseSuiteConfig(
        controller=controllers[0],
        houses=parse_houses(args.houses),
        routes_per_house=args.routes_per_house,
        noise=args.noise,
        seeds=tuple(args.seeds),
        model=args.model,
        max_steps_factor=args.max_steps_factor,
        threads=args.threads,
        workers=args.workers,
        oracle=args.oracle,
        json_path=args.json_path,
        camera=getattr(args, "camera", None),
    )
    result = run(cfg)
    print(markdown(result))
    if cfg.json_path is not None:
        md = Path(cfg.json_path).with_suffix(".md")
        print(f"wrote {cfg.json_path}, {md} and {result['plot']}")
    return 0
