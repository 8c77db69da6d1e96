"""`vtr eval --suite conditions`: repeat routes under changed conditions, over several seeds, and report
per condition how often the robot finished without touching anything, and how well it tracked.

Every route is taught once, noise-free, in the unchanged house. Each repeat then runs under one
condition (``CONDITIONS``: actuation noise, a start offset, repeat-time lighting, a changed room, a box on
the path), one actuation-noise seed, one controller (``CONTROLLERS``) and one model (fp32 or int8). A run
counts as completed only when it did what its condition expects (``condition_run.judged``): the repeat
finished on the route and the robot touched nothing; under ``box_on_path``, it stopped as ``blocked``
and touched nothing. The step limit scales with the
route: ``max_steps_factor`` times its subgoals, plus 50.

By default the routes are the held-out ones (sim2d/routes/heldout): written for this suite and never used
to choose a threshold or a rule. Tuning used the routes in sim2d/routes (see studies/matching_study.py).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vtr.evaluation.condition_run import (
    CONDITIONS,
    CONTROLLERS,
    cached_policy,
    run_once,
    step_compute_summary,
)
from vtr.evaluation.condition_tables import markdown
from vtr.evaluation.metrics import off_path
from vtr.evaluation.sensor_conditions import SENSORS
from vtr.runtime.status_line import Progress

HELDOUT_DIR = Path(__file__).resolve().parents[1] / "sim2d" / "routes" / "heldout"


@dataclass
class SuiteConfig:
    """One condition-suite run."""

    model: Path | None = None  # fp32 VelocityNet ONNX; None: the shipped one (vtr.models.find_model)
    int8_model: Path | None = None  # None: `<model stem>-int8.onnx` beside the model, if present
    routes: tuple[str, ...] = ()  # names in sim2d/routes/heldout or sim2d/routes, or paths; () = held-out
    conditions: tuple[str, ...] = tuple(CONDITIONS)
    seeds: tuple[int, ...] = (0, 1, 2)
    controllers: tuple[str, ...] = ("paper", "before", "after")
    models: tuple[str, ...] = ("fp32", "int8")
    max_steps_factor: float = 8.0  # step limit = factor * subgoals + 50 (subgoals: every 2nd taught step)
    dt: float = 0.1
    threads: int = 1
    workers: int = 2
    json_path: Path | None = None

    def __post_init__(self) -> None:
        from vtr.models import find_model

        try:
            self.model = find_model(self.model)
        except FileNotFoundError as err:
            raise ValueError(str(err)) from err
        if self.int8_model is None:
            sibling = self.model.with_name(self.model.stem + "-int8" + self.model.suffix)
            self.int8_model = sibling if sibling.is_file() else None
        if "int8" in self.models and (self.int8_model is None or not Path(self.int8_model).is_file()):
            raise ValueError(
                f"int8 model not found ({self.int8_model}); pass --int8-model or --suite-models fp32"
            )
        for kind, names, known in (
            ("condition", self.conditions, CONDITIONS),
            ("controller", self.controllers, CONTROLLERS),
            ("model", self.models, ("fp32", "int8")),
        ):
            unknown = [n for n in names if n not in known]
            if unknown or not names:
                raise ValueError(f"unknown or no {kind}s {unknown}; known: {', '.join(known)}")
        if not self.seeds:
            raise ValueError("give at least one seed")
        if not self.max_steps_factor > 0 or self.workers < 1 or self.threads < 1:
            raise ValueError("max_steps_factor must be > 0, workers and threads >= 1")
        route_paths(self.routes)  # fail early on a bad name


def route_paths(names: tuple[str, ...]) -> list[Path]:
    """ROUTE.json files: the held-out set when ``names`` is empty, else each name, path or folder."""
    from vtr.sim2d.routes import ROUTES_DIR

    if not names:
        return sorted(HELDOUT_DIR.glob("*.json"))
    out = []
    for name in names:
        if Path(name).is_dir():  # a folder of routes, e.g. sim2d/routes/heldout2
            out += sorted(Path(name).glob("*.json"))
            continue
        candidates = [Path(name), HELDOUT_DIR / f"{name}.json", ROUTES_DIR / f"{name}.json"]
        found = next((p for p in candidates if p.suffix == ".json" and p.is_file()), None)
        if found is None:
            raise ValueError(f"route not found: {name} (looked in {HELDOUT_DIR} and {ROUTES_DIR})")
        out.append(found)
    return out


def evaluate_task(task: tuple[Path, str, SuiteConfig]) -> list[dict[str, Any]]:
    """All seeds, controllers and models of one (route, condition): a process-pool task."""
    import tempfile

    from vtr.evaluation.conditions import PathBlocked, write_scene_house
    from vtr.evaluation.harness import teach

    path, cond_name, cfg = task
    os.environ.setdefault("OMP_NUM_THREADS", str(cfg.threads))
    cond = CONDITIONS[cond_name]
    models = {"fp32": cfg.model, "int8": cfg.int8_model}
    shape = tuple(cached_policy(cfg.model, cfg.threads).image_shape)
    # the robot's own camera (its field of view, height and sensor) is the same at teach and repeat
    route, script = teach(path, shape, cfg.dt, camera=cond.camera, sensor=SENSORS.get(cond.sensor or ""))
    task_key = {"route": path.stem, "condition": cond_name}
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        try:
            house = str(write_scene_house(cond.scene, Path(tmp), path=route.poses)) if cond.scene else "house"
        except ValueError as err:  # no free floor for a box beside this path, or the change blocks the path
            status = "path_blocked" if isinstance(err, PathBlocked) else "scene_not_placeable"
            blocked = {"status": status, "cause": str(err), "completed": False, "ran": False}
            return [
                {**task_key, "model": m, "controller": c, "seed": s, **blocked}
                for m in cfg.models
                for c in cfg.controllers
                for s in cfg.seeds
            ]
        for model in cfg.models:
            policy = cached_policy(Path(models[model]), cfg.threads)
            for ctrl in cfg.controllers:
                for seed in cfg.seeds:
                    run = run_once(route, script, cond, house, seed, CONTROLLERS[ctrl], policy, cfg)
                    out.append({**task_key, "model": model, "controller": ctrl, "seed": seed, **run})
    return out


# ------------------------------------------------------------------------------------- aggregation


def aggregate(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (controller, model, condition): rates over runs, errors over completed runs."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for r in runs:
        groups.setdefault((r["controller"], r["model"], r["condition"]), []).append(r)
    rows = []
    for (ctrl, model, cond), rs in groups.items():
        ran = [r for r in rs if r["ran"]]
        # errors over completed runs that drove the route: one stopped before a box (box_on_path) has none
        done = [r for r in ran if r["completed"] and r.get("status") != "blocked"]

        def mean(key: str, among: list[dict[str, Any]] = done) -> float | None:
            return float(np.mean([r[key] for r in among])) if among else None

        causes = Counter(r["cause"].split(":")[0] for r in ran if not r["completed"])
        boxed = [r for r in ran if r.get("box_face_m") is not None]
        rows.append(
            {
                "controller": ctrl,
                "model": model,
                "condition": cond,
                "runs": len(ran),
                "not_run": len(rs) - len(ran),
                "completed": sum(r["completed"] for r in ran),
                "completed_off_path": off_path(done),
                "completion_rate": sum(r["completed"] for r in ran) / len(ran) if ran else None,
                "mean_position_error_m": mean("position_error_m"),
                "max_position_error_m": mean("max_position_error_m"),
                "mean_yaw_error_deg": mean("yaw_error_deg"),
                "cross_track_m": mean("cross_track_m"),
                "final_position_m": mean("final_position_m"),
                "final_yaw_deg": mean("final_yaw_deg"),
                "runs_with_contact": sum(r["contacts"] > 0 for r in ran),
                "steps_per_taught_step": mean("steps_per_taught_step"),
                "failure_causes": dict(causes),
                "box_face_m": mean("box_face_m", boxed),  # the path box: the robot's centre to it at the end
            }
        )
    order = {n: i for i, n in enumerate(CONTROLLERS)}
    conds = {n: i for i, n in enumerate(CONDITIONS)}
    return sorted(rows, key=lambda r: (order[r["controller"]], r["model"], conds[r["condition"]]))


def run(cfg: SuiteConfig) -> dict[str, Any]:
    """Every (route, condition) task, in a process pool when workers > 1; writes JSON and Markdown."""
    paths = route_paths(cfg.routes)
    tasks = [(p, c, cfg) for p in paths for c in cfg.conditions]
    t0 = time.perf_counter()
    runs: list[dict[str, Any]] = []

    with Progress("condition suite (route x condition)", len(tasks)) as progress:  # stderr, a terminal only
        if cfg.workers > 1 and len(tasks) > 1:
            from vtr.training.pool import process_pool

            with process_pool(cfg.workers) as ex:  # Ctrl-C stops it at once
                for (path, cond, _), out in zip(tasks, ex.map(evaluate_task, tasks), strict=True):
                    runs += out
                    progress.advance(f"{path.stem} {cond}")
        else:
            for path, cond, c in tasks:
                runs += evaluate_task((path, cond, c))
                progress.advance(f"{path.stem} {cond}")
    result = {
        "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()},
        "routes": [p.stem for p in paths],
        "table": aggregate(runs),
        "step_compute": step_compute_summary(runs),
        "runs": runs,
        "wall_s": time.perf_counter() - t0,
    }
    if cfg.json_path is not None:
        import json

        from vtr.runtime.atomic import write_text_atomic

        write_text_atomic(cfg.json_path, json.dumps(result, indent=1))
        write_text_atomic(Path(cfg.json_path).with_suffix(".md"), markdown(result))
    return result


# --------------------------------------------------------------------------- CLI (inside `vtr eval`)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The suite's options, added to `vtr eval` (which owns --model, --int8-model, --routes, --json, ...)."""
    g = parser.add_argument_group("condition suite (--suite conditions)")
    g.add_argument(
        "--suite",
        choices=("conditions", "pace"),
        default=None,
        help="run a condition suite, or the realtime pace (evaluation/realtime_pace.py), instead",
    )
    g.add_argument(
        "--conditions", nargs="*", default=list(CONDITIONS), help="conditions (default: all: %(default)s)"
    )
    g.add_argument(
        "--seeds", type=int, nargs="*", default=[0, 1, 2], help="noise seeds (default: %(default)s)"
    )
    g.add_argument(
        "--controllers",
        nargs="*",
        default=None,
        help=f"controllers among {', '.join(CONTROLLERS)} (default: paper before after; with "
        "--houses: after)",
    )
    g.add_argument(
        "--suite-models", nargs="*", default=["fp32", "int8"], help="fp32 and/or int8 (default: %(default)s)"
    )
    g.add_argument(
        "--max-steps-factor",
        type=float,
        default=8.0,
        help="step limit = factor x the route's subgoals + 50 (default: %(default)s)",
    )


def run_cli(args: argparse.Namespace) -> int:
    try:
        cfg = SuiteConfig(
            model=args.model,
            int8_model=args.int8_model,
            routes=tuple(args.routes),
            conditions=tuple(args.conditions),
            seeds=tuple(args.seeds),
            controllers=tuple(args.controllers or SuiteConfig.controllers),
            models=tuple(args.suite_models),
            max_steps_factor=args.max_steps_factor,
            threads=args.threads,
            workers=args.workers,
            json_path=args.json_path,
        )
    except ValueError as err:
        print(f"vtr eval: {err}", file=sys.stderr)
        return 2
    result = run(cfg)
    print(markdown(result))
    if cfg.json_path is not None:
        print(f"wrote {cfg.json_path} and {Path(cfg.json_path).with_suffix('.md')}")
    return 0
