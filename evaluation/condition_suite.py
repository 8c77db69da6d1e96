"""`vtr eval --suite conditions`: repeat routes under changed conditions, over several seeds, and report
per condition how often the robot finished without touching anything, and how well it tracked.

Every route is taught once, noise-free, in the unchanged house. Each repeat then runs under one
condition (``CONDITIONS``: actuation noise, a start offset, repeat-time lighting, a changed room), one
actuation-noise seed, one controller (``CONTROLLERS``) and one model (fp32 or int8). A run counts as
completed only when the repeat finished and the robot touched nothing. The step limit scales with the
route: ``max_steps_factor`` times its subgoals, plus 50.

By default the routes are the held-out ones (sim2d/routes/heldout): written for this suite and never used
to choose a threshold or a rule. Tuning used the routes in sim2d/routes (see evaluation.matching_study).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections import Counter
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from vtr.evaluation.condition_tables import markdown
from vtr.evaluation.conditions import LIGHTING, PATH_SCENES, SCENES
from vtr.evaluation.metrics import off_path
from vtr.runtime.controller import ControllerConfig
from vtr.runtime.matching import MatchConfig

HELDOUT_DIR = Path(__file__).resolve().parents[1] / "sim2d" / "routes" / "heldout"


@dataclass(frozen=True)
class Condition:
    """What differs at repeat time: actuation noise, start offset (lateral m, yaw deg; its sign flips
    with odd seeds), the light on the camera image (a LIGHTING key) and the house (a SCENES key)."""

    noise: float = 0.05
    offset: tuple[float, float] = (0.0, 0.0)
    light: str | None = None
    scene: str | None = None


CONDITIONS: dict[str, Condition] = {
    "noise_0.05": Condition(),
    "noise_0.10": Condition(noise=0.10),
    "offset_5cm_5deg": Condition(offset=(0.05, 5.0)),
    "offset_10cm_10deg": Condition(offset=(0.10, 10.0)),
    **{name: Condition(light=name) for name in LIGHTING},
    **{name: Condition(scene=name) for name in (*SCENES, *PATH_SCENES)},
}


@dataclass(frozen=True)
class Method:
    """How the runtime repeats: the controller's settings, and whether the current image is recoloured to
    the subgoal's light before the policy sees it (runtime.light)."""

    controller: ControllerConfig
    match_light: bool = False
    side_ramp: bool = True  # with match_light: also even out a left-to-right gain


AFTER = ControllerConfig()  # patch matching, hybrid thresholds, zero bias, lost and contact stops, turns held
CONTROLLERS: dict[str, Method] = {
    "paper": Method(ControllerConfig.paper()),  # Algorithm 1: raw error, e_m = 17
    "before": Method(ControllerConfig.before()),  # the previous default: raw error, one e_m per route
    "after": Method(AFTER, match_light=True),
    # ablations of "after", one part off each
    "after_no_light_matching": Method(AFTER),
    "after_no_side_ramp": Method(AFTER, match_light=True, side_ramp=False),
    "after_raw_matching": Method(replace(AFTER, match=MatchConfig.paper()), match_light=True),
    "after_route_threshold": Method(replace(AFTER, e_m_mode="calibrated", pass_ratio=0.0), match_light=True),
    "after_per_subgoal": Method(replace(AFTER, e_m_mode="per_subgoal", pass_ratio=1.0), match_light=True),
    "after_no_hold_turns": Method(replace(AFTER, hold_turns=False), match_light=True),
    "after_plateau_2x": Method(replace(AFTER, jump_factor=2.0), match_light=True),  # the previous bound
    "after_no_progress_gate": Method(replace(AFTER, progress_gate=0.0), match_light=True),
    "after_match_ramp": Method(replace(AFTER, match_ramp=True), match_light=True),
    "after_gate_0.7": Method(replace(AFTER, progress_gate=0.7), match_light=True),
    "after_gate_1.0": Method(replace(AFTER, progress_gate=1.0), match_light=True),
    "after_no_idle": Method(replace(AFTER, idle_steps=0), match_light=True),  # wait out the stall guard
    "after_settle_0": Method(replace(AFTER, settle_steps=0), match_light=True),
    "after_prior_0.3": Method(replace(AFTER, taught_prior=0.3), match_light=True),
    "after_no_zero_bias": Method(replace(AFTER, zero_bias=0.0), match_light=True),
    "after_gate_0.5": Method(replace(AFTER, progress_gate=0.5), match_light=True),  # the previous gate
    "after_per_subgoal_settle_0": Method(
        replace(AFTER, e_m_mode="per_subgoal", pass_ratio=1.0, settle_steps=0), match_light=True
    ),
}


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
        for kind, names, known in (("condition", self.conditions, CONDITIONS), ("controller", self.controllers,
                                   CONTROLLERS), ("model", self.models, ("fp32", "int8"))):  # fmt: skip
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


# ---------------------------------------------------------------------------------------------- runs

_POLICIES: dict[tuple[str, int], Any] = {}  # per worker process: ONNX sessions by (path, threads)


def cached_policy(path: Path, threads: int) -> Any:
    """One OnnxPolicy per (model, threads) in this process."""
    from vtr.runtime.policy import OnnxPolicy

    key = (str(path), threads)
    if key not in _POLICIES:
        _POLICIES[key] = OnnxPolicy(path, threads=threads)
    return _POLICIES[key]


def _start(pose: np.ndarray, offset: tuple[float, float], seed: int) -> tuple[float, float, float]:
    x, y, yaw = (float(v) for v in pose)
    sign = 1.0 if seed % 2 == 0 else -1.0
    lateral, dyaw = sign * offset[0], sign * math.radians(offset[1])
    return (x - math.sin(yaw) * lateral, y + math.cos(yaw) * lateral, yaw + dyaw)


def switch_lag(taught: np.ndarray, switch_poses: dict[int, tuple[float, float, float]]) -> float | None:
    """Mean along-track offset (m) of the robot from each subgoal's taught pose when the controller
    switched past it: negative = the robot was still short of the subgoal (the index ran ahead)."""
    if not switch_poses:
        return None
    k = np.fromiter(switch_poses, dtype=int)
    at = np.asarray([switch_poses[i] for i in k], dtype=np.float64)
    p = np.asarray(taught, dtype=np.float64)[k]
    return float(np.mean((at[:, 0] - p[:, 0]) * np.cos(p[:, 2]) + (at[:, 1] - p[:, 1]) * np.sin(p[:, 2])))


def run_once(route: Any, script: Any, cond: Condition, house: str, seed: int, method: Method,
             policy: Any, cfg: Any, keep_path: bool = False) -> dict[str, Any]:  # fmt: skip
    """One repeat under ``cond`` (evaluation.runs, the `vtr eval` harness's loop); its scores plus the
    status, the failure's cause and the control steps per taught control step (``keep_path``: and the
    repeated x, y in mm precision). ``cfg`` needs dt and max_steps_factor (a SuiteConfig)."""
    from vtr.evaluation.conditions import LitRobot
    from vtr.evaluation.runs import repeat_closed_loop
    from vtr.evaluation.scoring import score
    from vtr.runtime.light import LightMatchedPolicy
    from vtr.sim2d import CameraConfig, SimConfig, Simulator
    from vtr.sim2d.local_robot import LocalRobot

    h, w = route.images.shape[1:3]
    robot: Any = LocalRobot(Simulator(SimConfig(camera=CameraConfig(width=w, height=h), noise=cond.noise,
                                                house=house)))  # fmt: skip
    if cond.light:
        robot = LitRobot(robot, LIGHTING[cond.light])
    if method.match_light:
        policy = LightMatchedPolicy(policy, side_ramp=method.side_ramp)
    start = _start(route.poses[0], cond.offset, seed)
    try:
        log = repeat_closed_loop(robot, policy, route, start, cfg, seed, controller_cfg=method.controller)
    except ValueError as err:
        if "not free space" not in str(err):
            raise
        return {"status": "start_blocked", "cause": str(err), "completed": False, "ran": False}
    s = score(route, log)
    touched = log.collisions > 0
    if log.outcome == "finished":
        cause = "finished but touched furniture" if touched else ""
    else:
        cause = f"{log.outcome}: {log.detail}" if log.detail else log.outcome
    return {
        "ran": True,
        "status": log.outcome,
        "completed": bool(log.outcome == "finished" and not touched),
        "cause": cause,
        "contacts": log.collisions,
        "subgoals_reached": log.subgoals_reached,
        "subgoals": len(route),
        "steps": log.steps,
        "steps_per_taught_step": log.steps / max(1, round(script.duration / cfg.dt)),
        "position_error_m": s["position_error_m"]["mean"],
        "max_position_error_m": s["position_error_m"]["max"],
        "yaw_error_deg": s["yaw_error_deg"]["mean"],
        "cross_track_m": s["mean_cross_track_error_m"],
        "final_position_m": s["final_pose_error"]["position_m"],
        "final_yaw_deg": abs(s["final_pose_error"]["yaw_deg"]),
        "switch_lag_m": switch_lag(route.poses, log.switch_poses),
        **({"path": np.round(np.asarray(log.poses)[:, :2], 3).tolist()} if keep_path else {}),
    }


def evaluate_task(task: tuple[Path, str, SuiteConfig]) -> list[dict[str, Any]]:
    """All seeds, controllers and models of one (route, condition): a process-pool task."""
    import tempfile

    from vtr.evaluation.conditions import PathBlocked, write_scene_house
    from vtr.evaluation.harness import teach

    path, cond_name, cfg = task
    os.environ.setdefault("OMP_NUM_THREADS", str(cfg.threads))
    cond = CONDITIONS[cond_name]
    models = {"fp32": cfg.model, "int8": cfg.int8_model}
    route, script = teach(path, tuple(cached_policy(cfg.model, cfg.threads).image_shape), cfg.dt)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        try:
            house = str(write_scene_house(cond.scene, Path(tmp), path=route.poses)) if cond.scene else "house"
        except ValueError as err:  # no free floor for a box beside this path, or the change blocks the path
            status = "path_blocked" if isinstance(err, PathBlocked) else "scene_not_placeable"
            blocked = {"status": status, "cause": str(err), "completed": False, "ran": False}
            return [{"route": path.stem, "condition": cond_name, "model": m, "controller": c, "seed": s, **blocked}
                    for m in cfg.models for c in cfg.controllers for s in cfg.seeds]  # fmt: skip
        for model in cfg.models:
            policy = cached_policy(Path(models[model]), cfg.threads)
            for ctrl in cfg.controllers:
                for seed in cfg.seeds:
                    run = run_once(route, script, cond, house, seed, CONTROLLERS[ctrl], policy, cfg)
                    out.append({"route": path.stem, "condition": cond_name, "model": model, "controller": ctrl,
                                "seed": seed, **run})  # fmt: skip
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
        done = [r for r in ran if r["completed"]]

        def mean(key: str, among: list[dict[str, Any]] = done) -> float | None:
            return float(np.mean([r[key] for r in among])) if among else None

        causes = Counter(r["cause"].split(":")[0] for r in ran if not r["completed"])
        rows.append({
            "controller": ctrl, "model": model, "condition": cond, "runs": len(ran),
            "not_run": len(rs) - len(ran), "completed": len(done), "completed_off_path": off_path(done),
            "completion_rate": len(done) / len(ran) if ran else None,
            "mean_position_error_m": mean("position_error_m"), "max_position_error_m": mean("max_position_error_m"),
            "mean_yaw_error_deg": mean("yaw_error_deg"), "cross_track_m": mean("cross_track_m"),
            "final_position_m": mean("final_position_m"), "final_yaw_deg": mean("final_yaw_deg"),
            "runs_with_contact": sum(r["contacts"] > 0 for r in ran),
            "steps_per_taught_step": mean("steps_per_taught_step"),
            "failure_causes": dict(causes),
        })  # fmt: skip
    order = {n: i for i, n in enumerate(CONTROLLERS)}
    conds = {n: i for i, n in enumerate(CONDITIONS)}
    return sorted(rows, key=lambda r: (order[r["controller"]], r["model"], conds[r["condition"]]))


def run(cfg: SuiteConfig) -> dict[str, Any]:
    """Every (route, condition) task, in a process pool when workers > 1; writes JSON and Markdown."""
    paths = route_paths(cfg.routes)
    tasks = [(p, c, cfg) for p in paths for c in cfg.conditions]
    t0 = time.perf_counter()
    runs: list[dict[str, Any]] = []

    def progress(done: int) -> None:
        print(f"condition suite: {done}/{len(tasks)} route x condition tasks, {time.perf_counter() - t0:.0f} s",
              file=sys.stderr, flush=True)  # fmt: skip

    if cfg.workers > 1 and len(tasks) > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(max_workers=cfg.workers, mp_context=mp.get_context("spawn")) as ex:
            for k, out in enumerate(ex.map(evaluate_task, tasks), 1):
                runs += out
                progress(k)
    else:
        for k, task in enumerate(tasks, 1):
            runs += evaluate_task(task)
            progress(k)
    result = {
        "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()},
        "routes": [p.stem for p in paths],
        "table": aggregate(runs),
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
    g.add_argument("--suite", choices=("conditions",), default=None, help="run a condition suite instead")
    g.add_argument(
        "--conditions", nargs="*", default=list(CONDITIONS), help="conditions (default: all: %(default)s)"
    )
    g.add_argument(
        "--seeds", type=int, nargs="*", default=[0, 1, 2], help="noise seeds (default: %(default)s)"
    )
    g.add_argument("--controllers", nargs="*", default=None,
                   help=f"controllers among {', '.join(CONTROLLERS)} (default: paper before after; with "
                        "--houses: after)")  # fmt: skip
    g.add_argument(
        "--suite-models", nargs="*", default=["fp32", "int8"], help="fp32 and/or int8 (default: %(default)s)"
    )
    g.add_argument("--max-steps-factor", type=float, default=8.0,
                   help="step limit = factor x the route's subgoals + 50 (default: %(default)s)")  # fmt: skip


def run_cli(args: argparse.Namespace) -> int:
    try:
        cfg = SuiteConfig(model=args.model, int8_model=args.int8_model, routes=tuple(args.routes),
                          conditions=tuple(args.conditions), seeds=tuple(args.seeds),
                          controllers=tuple(args.controllers or SuiteConfig.controllers), models=tuple(args.suite_models),
                          max_steps_factor=args.max_steps_factor, threads=args.threads, workers=args.workers,
                          json_path=args.json_path)  # fmt: skip
    except ValueError as err:
        print(f"vtr eval: {err}", file=sys.stderr)
        return 2
    result = run(cfg)
    print(markdown(result))
    if cfg.json_path is not None:
        print(f"wrote {cfg.json_path} and {Path(cfg.json_path).with_suffix('.md')}")
    return 0
