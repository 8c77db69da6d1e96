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
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vtr.benchmarks import metrics
from vtr.runtime.atomic import atomic_path, write_text_atomic
from vtr.runtime.contracts import CONTROL_DT, Policy
from vtr.runtime.controller import Action
from vtr.sim2d.routes import ROUTES_DIR

#: The paper's three scenarios (route file stems) and its Tables 1 and 2.
PAPER_ROUTES = ("translation", "rotation", "translation_rotation")
PAPER = {
    "translation": {"unit": "m", "min": 3.37e-6, "max": 0.025, "mean": 0.012, "std": 6.98e-3},
    "translation_rotation": {"unit": "m", "min": 2.13e-4, "max": 8.825e-3, "mean": 5.04e-3, "std": 2.203e-3},
    "rotation": {"unit": "deg", "min": 6.36e-3, "max": 5.053, "mean": 1.578, "std": 1.187},
}
QUICK_ROUTES = ("translation",)


@dataclass
class EvalConfig:
    """Settings of one closed-loop evaluation."""

    model: Path  # fp32 VelocityNet ONNX
    routes: tuple[str, ...] = ()  # route names (stems in sim2d/routes) or ROUTE.json paths; () = all
    noise: float = 0.05  # actuation noise of the repeat runs (SimConfig.noise: per-run speed-scale and curvature bias + per-step jitter)
    offset: tuple[float, float, float] = (
        0.03,
        0.03,
        3.0,
    )  # start offset: dx, dy (m, robot frame), dyaw (deg)
    int8_model: Path | None = None  # int8 twin; None -> `<model stem>-int8.onnx` beside the model, if present
    ablation_model: Path | None = None  # a VelocityNet trained with w2 = 0 (ONNX)
    viewnet: Path | None = None  # ViewNet checkpoint for the online-MPC baseline; None -> no MPC
    mpc_routes: tuple[str, ...] = PAPER_ROUTES  # the MPC is slow: these routes only, noise scenario only
    mpc_samples: int = 32  # candidate (v, w) sequences per MPC step
    mpc_iterations: int = 2  # cross-entropy refinements of the candidate distribution
    open_loop: bool = True  # run the open-loop replay baseline
    oracle: bool = (
        False  # pose-oracle diagnostic (true poses; the floor e_m switching leaves), noise scenario only
    )
    e_m: float | None = None  # fixed switch threshold (the paper's 17); None = the runtime's calibrated e_m
    dt: float = CONTROL_DT  # s each command is applied for (the paper's control step)
    max_steps_factor: float = 8.0  # give up after factor * subgoals + 50 control steps
    seed: int = 0  # actuation noise seed
    threads: int = 1  # onnxruntime / torch threads per worker
    workers: int = 2  # processes over routes
    quick: bool = False  # one short route, one scenario, no MPC: for the tests
    json_path: Path | None = None
    plots_dir: Path | None = None
    markdown_path: Path | None = None  # default: beside the JSON file, same stem + .md

    def __post_init__(self) -> None:
        self.model = Path(self.model)
        if not self.model.is_file():
            raise ValueError(f"model file not found: {self.model}")
        if not 0.0 <= self.noise <= 1.0:
            raise ValueError(f"noise must be in [0, 1], got {self.noise}")
        if len(self.offset) != 3 or not all(math.isfinite(o) for o in self.offset):
            raise ValueError(f"offset must be three finite numbers (dx m, dy m, dyaw deg), got {self.offset}")
        for name in ("ablation_model", "viewnet"):
            value = getattr(self, name)
            if value is not None and not Path(value).exists():
                raise ValueError(f"{name} not found: {value}")
        if self.int8_model is None:
            sibling = self.model.with_name(self.model.stem + "-int8" + self.model.suffix)
            self.int8_model = sibling if sibling.is_file() else None
        elif not Path(self.int8_model).is_file():
            raise ValueError(f"int8 model not found: {self.int8_model}")
        if self.mpc_samples < 2 or self.mpc_iterations < 1:
            raise ValueError(f"mpc_samples must be >= 2 and mpc_iterations >= 1, got {self.mpc_samples}, "
                             f"{self.mpc_iterations}")  # fmt: skip
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


# ---------------------------------------------------------------- routes and teach


def route_files(names: tuple[str, ...]) -> list[Path]:
    """ROUTE.json paths for names (stems in sim2d/routes) or paths; all routes when names is empty."""
    if not names:
        files = sorted(ROUTES_DIR.glob("*.json"))
        if not files:
            raise ValueError(f"no routes in {ROUTES_DIR}")
        # The paper's scenarios first, in the paper's order.
        return sorted(files, key=lambda p: (p.stem not in PAPER_ROUTES, PAPER_ROUTES.index(p.stem)
                                            if p.stem in PAPER_ROUTES else 0, p.stem))  # fmt: skip
    out = []
    for name in names:
        path = Path(name)
        if not path.suffix:
            path = ROUTES_DIR / f"{name}.json"
        if not path.is_file():
            raise ValueError(f"route not found: {name} (looked at {path})")
        out.append(path)
    return out


def make_robot(noise: float, image_size: tuple[int, int]) -> Any:
    from vtr.sim2d import CameraConfig, SimConfig, Simulator
    from vtr.sim2d.local_robot import LocalRobot

    h, w = image_size
    return LocalRobot(Simulator(SimConfig(camera=CameraConfig(width=w, height=h), noise=noise)))


def teach(script_path: Path, image_size: tuple[int, int], dt: float) -> tuple[Any, Any]:
    """Drive the scripted route noise-free with `runtime.teach`; returns (Route, RouteScript)."""
    from vtr.runtime.route_script import load_route_script
    from vtr.runtime.teach import TeachConfig
    from vtr.runtime.teach import teach as teach_route

    script = load_route_script(script_path)
    robot = make_robot(0.0, image_size)
    return teach_route(robot, script, TeachConfig(dt=dt, seed=0)), script


# ---------------------------------------------------------------- one repeat run


@dataclass
class RunLog:
    """What one repeat run did: poses for scoring, commands, and how far it got."""

    poses: list[tuple[float, float, float]] = field(default_factory=list)
    commands: list[tuple[float, float]] = field(default_factory=list)
    switch_poses: dict[int, tuple[float, float, float]] = field(
        default_factory=dict
    )  # subgoal -> pose at switch
    subgoals_reached: int = 0
    steps: int = 0
    sim_time: float = 0.0
    collisions: int = 0
    outcome: str = ""
    policy_ms: list[float] = field(default_factory=list)
    e_m: float | None = None


class PoseOracle:
    """Diagnostic upper bound, not a visual method: steers to the subgoal's taught pose using true poses.

    It runs inside the same Repeater and controller as VelocityNet, so the subgoal switching (e_m on
    images) is identical; its errors are the floor that switching rule leaves, and VelocityNet's distance
    above it is what the network costs. ``bind`` hands it the robot (true poses) and the controller (the
    subgoal index it steers to).
    """

    def __init__(
        self, v_max: float, w_max: float, horizon: int, dt: float, image_shape: tuple[int, int]
    ) -> None:
        self.v_max, self.w_max, self.horizon, self.dt = v_max, w_max, horizon, dt
        self.image_shape = image_shape
        self.position_tolerance = 0.01  # m: closer than this, only the heading is corrected
        self.robot: Any = None
        self.controller: Any = None
        self.route: Any = None

    def bind(self, robot: Any, controller: Any, route: Any) -> None:
        self.robot, self.controller, self.route = robot, controller, route

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        assert self.robot is not None and self.controller is not None
        index = min(self.controller.index, len(self.route) - 1)
        gx, gy, gyaw = self.route.poses[index]
        x, y, yaw = self.robot.last.pose
        c, s = math.cos(yaw), math.sin(yaw)
        ex, ey = c * (gx - x) + s * (gy - y), -s * (gx - x) + c * (gy - y)  # goal in the robot frame
        eyaw = float(metrics.wrap_angle(gyaw - yaw))
        rho, alpha = math.hypot(ex, ey), math.atan2(ey, ex)
        # a differential drive cannot slide sideways: turn toward the goal point (backing up when it lies
        # behind), drive, and once there turn to the goal's heading; each gap closed in about two steps
        if rho > self.position_tolerance:
            backwards = abs(alpha) > math.pi / 2
            heading = float(metrics.wrap_angle(alpha - math.pi)) if backwards else alpha
            v = (-1.0 if backwards else 1.0) * rho * max(math.cos(heading), 0.0) / (2 * self.dt)
            w = heading / (2 * self.dt)
        else:
            v, w = 0.0, eyaw / (2 * self.dt)
        v, w = float(np.clip(v, -self.v_max, self.v_max)), float(np.clip(w, -self.w_max, self.w_max))
        return np.tile(np.array([[v], [w]], dtype=np.float32), (1, self.horizon))


def repeat_closed_loop(
    robot: Any, policy: Policy, route: Any, start: tuple[float, float, float], cfg: EvalConfig, seed: int
) -> RunLog:
    """The runtime's Repeater (Algorithm 1 + controller) on images; poses are kept for scoring only."""
    from vtr.runtime.controller import Controller, ControllerConfig
    from vtr.runtime.repeater import RepeatConfig, Repeater, StepRecord

    log = RunLog()
    first = robot.reset(pose=start, seed=seed)
    log.poses.append(first.pose)
    ccfg = ControllerConfig() if cfg.e_m is None else ControllerConfig(e_m_mode="fixed", e_m=cfg.e_m)
    rcfg = RepeatConfig(controller=ccfg, dt=cfg.dt, max_steps=int(cfg.max_steps_factor * len(route) + 50))
    controller = Controller(route.images, ccfg)
    if isinstance(policy, PoseOracle):
        policy.bind(robot, controller, route)

    def on_step(record: StepRecord) -> None:
        # the subgoals reached on this image were reached at the pose it was taken from
        for event in record.events:
            if event.action is Action.ADVANCE:
                log.switch_poses.setdefault(event.index - 1, record.pose)
        if record.commanded:
            log.commands.append((record.v, record.w))
            log.policy_ms.append(record.latency_ms["policy"])
            log.poses.append(robot.last.pose)
            log.collisions += int(robot.last.collided)

    summary = Repeater(robot, policy, route, controller, config=rcfg, on_step=on_step).run()
    if summary.completed:
        for k in range(len(route)):
            log.switch_poses.setdefault(k, log.poses[-1])
    log.subgoals_reached = summary.subgoals_reached
    log.steps = summary.steps
    log.outcome = summary.status.value
    log.e_m = summary.e_m
    log.sim_time = float(summary.sim_time_s)
    return log


def repeat_open_loop(
    robot: Any, script: Any, start: tuple[float, float, float], seed: int, dt: float
) -> RunLog:
    """Replay the taught commands blind (the script's segments, step by step as taught): no correction."""
    log = RunLog()
    obs = robot.reset(pose=start, seed=seed)
    log.poses.append(obs.pose)
    t0 = obs.stamp
    for segment in script.segments:
        for _ in range(max(1, round(segment.duration / dt))):
            obs = robot.step(segment.v, segment.w, dt)
            robot.stop()
            log.steps += 1
            log.collisions += int(obs.collided)
            log.poses.append(obs.pose)
            log.commands.append((segment.v, segment.w))
    log.outcome = "replayed"
    log.sim_time = float(obs.stamp - t0)
    return log


def score(route: Any, log: RunLog, open_loop: bool = False) -> dict[str, Any]:
    """All metrics of one run, plus its trajectory (rounded) for plots.

    Open-loop replay has no subgoals to reach: it always plays to the end, so its completion is 1 and
    only its errors say how far it drifted.
    """
    repeated = np.asarray(log.poses, dtype=np.float64)
    cmds = np.asarray(log.commands, dtype=np.float64).reshape(-1, 2)
    reached = len(route) if open_loop else log.subgoals_reached
    out = metrics.route_metrics(route.poses, repeated, cmds, reached)
    switch = {k: p for k, p in log.switch_poses.items() if k < len(route)}
    if switch:
        idx = np.array(sorted(switch))
        sp = np.array([switch[k] for k in idx])
        tp = route.poses[idx]
        out["switch_position_error_m"] = metrics.error_stats(np.hypot(*(sp[:, :2] - tp[:, :2]).T))
        out["switch_yaw_error_deg"] = metrics.error_stats(
            np.degrees(np.abs(metrics.wrap_angle(sp[:, 2] - tp[:, 2])))
        )
        out["switch_poses"] = {"index": idx.tolist(), "poses": np.round(sp, 5).tolist()}
    out.update(
        steps=log.steps,
        sim_time_s=log.sim_time,
        collisions=log.collisions,
        outcome=log.outcome,
        e_m=log.e_m,
        subgoals_reached=reached,
        subgoals=len(route),
        repeated_poses=np.round(repeated, 5).tolist(),
    )
    if log.policy_ms:
        ms = np.asarray(log.policy_ms)
        out["policy_ms"] = {"p50": float(np.percentile(ms, 50)), "p99": float(np.percentile(ms, 99)),
                            "mean": float(ms.mean())}  # fmt: skip
    return out


# ---------------------------------------------------------------- policies


class ViewNetMPC:
    """Online MPC: at every step, search (v, w) sequences by rolling ViewNet forward (cross-entropy method).

    Candidates are N-step sequences of (v, w) inside the limits; each is rolled through ViewNet from the
    current image and scored by the mean absolute difference of every predicted image to the subgoal (the
    last one weighted double). The best sequence is returned as a (2, N) array like VelocityNet's output.
    """

    def __init__(
        self, checkpoint: Path, horizon: int, samples: int, iterations: int, threads: int, seed: int
    ):
        import torch

        from vtr.training.train import load_model

        torch.set_num_threads(threads)
        kind, self.net, _ = load_model(checkpoint)
        if kind != "viewnet":
            raise ValueError(f"{checkpoint} holds a {kind}, not a viewnet")
        self.torch = torch
        self.image_shape = (int(self.net.cfg.image_size), int(self.net.cfg.image_size))
        self.horizon, self.samples, self.iterations = horizon, samples, iterations
        self.v_max, self.w_max = float(self.net.cfg.v_max), float(self.net.cfg.w_max)
        self.rng = np.random.default_rng(seed)
        self._mean = np.zeros((horizon, 2))

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        from vtr.runtime.preprocess import to_nchw

        torch = self.torch
        limits = np.array([self.v_max, self.w_max])
        cur = torch.from_numpy(to_nchw(current))  # (1, 3, H, W)
        goal = torch.from_numpy(to_nchw(subgoal))
        mean, std = np.vstack([self._mean[1:], np.zeros((1, 2))]), limits * 0.5  # warm start: shifted plan
        best, best_cost = np.zeros((self.horizon, 2)), math.inf
        for _ in range(self.iterations):
            cand = self.rng.normal(mean, std, size=(self.samples, self.horizon, 2))
            cand[0] = mean
            cand[1] = 0.0
            cand = np.clip(cand, -limits, limits)
            costs = self._costs(cur, goal, cand)
            order = np.argsort(costs)
            if costs[order[0]] < best_cost:
                best, best_cost = cand[order[0]], float(costs[order[0]])
            elite = cand[order[: max(2, self.samples // 8)]]
            mean, std = elite.mean(axis=0), elite.std(axis=0) + 0.02 * limits
        self._mean = best
        return best.T.astype(np.float32)  # (2, N)

    def _costs(self, cur: Any, goal: Any, cand: np.ndarray) -> np.ndarray:
        torch = self.torch
        k = cand.shape[0]
        vel = torch.from_numpy(cand.astype(np.float32))  # (K, N, 2)
        with torch.inference_mode():
            img = cur.expand(k, -1, -1, -1)  # (K, 3, H, W)
            cost = torch.zeros(k)
            for j in range(self.horizon):
                img = self.net(img, vel[:, j])  # (K, 3, H, W)
                weight = 2.0 if j == self.horizon - 1 else 1.0
                cost += weight * (img - goal).abs().mean(dim=(1, 2, 3))
        return cost.numpy()


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


# ---------------------------------------------------------------- aggregation and tables


def _paper_stat(
    route_result: dict[str, Any], method: str, scenario: str = "noise"
) -> dict[str, float] | None:
    run = route_result["scenarios"].get(scenario, {}).get(method)
    if run is None:
        return None
    key = "yaw_error_deg" if route_result["name"] == "rotation" else "position_error_m"
    return run[key]


def aggregate(routes: list[dict[str, Any]]) -> dict[str, Any]:
    """Per scenario and method: completion rate and mean errors over routes (own routes separately)."""
    out: dict[str, Any] = {}
    scenarios = sorted({s for r in routes for s in r["scenarios"]})
    for scen in scenarios:
        out[scen] = {}
        methods = sorted({m for r in routes for m in r["scenarios"].get(scen, {})})
        for method in methods:
            runs = [
                (r, r["scenarios"][scen][method]) for r in routes if method in r["scenarios"].get(scen, {})
            ]
            own = [run for r, run in runs if not r["paper_scenario"]]
            out[scen][method] = {
                "routes": len(runs),
                "completed": sum(run["completed"] for _, run in runs),
                "own_routes": len(own),
                "own_completed": sum(run["completed"] for run in own),
                "mean_completion": float(np.mean([run["completion"] for _, run in runs])),
                "mean_position_error_m": float(np.mean([run["position_error_m"]["mean"] for _, run in runs])),
                "mean_max_position_error_m": float(
                    np.mean([run["position_error_m"]["max"] for _, run in runs])
                ),
                "mean_cross_track_error_m": float(
                    np.mean([run["mean_cross_track_error_m"] for _, run in runs])
                ),
                "mean_final_position_error_m": float(
                    np.mean([run["final_pose_error"]["position_m"] for _, run in runs])
                ),
                "mean_abs_dv": float(np.mean([run["smoothness"]["mean_abs_dv"] for _, run in runs])),
                "mean_abs_dw": float(np.mean([run["smoothness"]["mean_abs_dw"] for _, run in runs])),
                "policy_ms_p50": float(
                    np.median([run["policy_ms"]["p50"] for _, run in runs if "policy_ms" in run])
                )
                if any("policy_ms" in run for _, run in runs)
                else None,
            }
    return out


def bar_checks(routes: list[dict[str, Any]], agg: dict[str, Any]) -> dict[str, Any]:
    """Issue 5's bar, each item with the measured value and whether it holds (None: not measured)."""
    by_name = {r["name"]: r for r in routes}
    checks: dict[str, Any] = {}

    def stat(name: str) -> dict[str, Any] | None:
        return _paper_stat(by_name[name], "velocitynet") if name in by_name else None

    for name in PAPER_ROUTES:
        run = by_name.get(name, {}).get("scenarios", {}).get("noise", {}).get("velocitynet")
        checks[f"{name}_completed"] = None if run is None else bool(run["completed"])
    t, tr, rot = stat("translation"), stat("translation_rotation"), stat("rotation")
    checks["translation_mean_le_0.012"] = None if t is None else t["mean"] <= 0.012
    checks["translation_max_le_0.025"] = None if t is None else t["max"] <= 0.025
    checks["translation_rotation_mean_le_0.00504"] = None if tr is None else tr["mean"] <= 0.00504
    checks["rotation_mae_le_1.578"] = None if rot is None else rot["mean"] <= 1.578
    checks["rotation_max_le_5.053"] = None if rot is None else rot["max"] <= 5.053
    vn = agg.get("noise", {}).get("velocitynet")
    if vn and vn["own_routes"]:
        checks["own_routes_completed_ge_90pct"] = vn["own_completed"] / vn["own_routes"] >= 0.9
    else:
        checks["own_routes_completed_ge_90pct"] = None
    ol = agg.get("noise", {}).get("open_loop")
    checks["beats_open_loop_cross_track"] = (
        None if not (vn and ol) else vn["mean_cross_track_error_m"] < ol["mean_cross_track_error_m"]
    )
    vo, oo = agg.get("offset", {}).get("velocitynet"), agg.get("offset", {}).get("open_loop")
    checks["beats_open_loop_cross_track_offset_start"] = (
        None if not (vo and oo) else vo["mean_cross_track_error_m"] < oo["mean_cross_track_error_m"]
    )
    # int8 is judged by closed-loop results: its paper-metric mean within 10% of fp32's on each paper route
    ratios = []
    for name in PAPER_ROUTES:
        if name in by_name:
            fp, q = _paper_stat(by_name[name], "velocitynet"), _paper_stat(by_name[name], "velocitynet_int8")
            if fp is not None and q is not None:
                ratios.append(q["mean"] / max(fp["mean"], 1e-12))
    checks["int8_within_10pct_of_fp32"] = bool(max(ratios) <= 1.10) if ratios else None
    # the stretch goal: half the paper's errors
    checks["half_paper_translation_mean"] = None if t is None else t["mean"] <= 0.006
    checks["half_paper_translation_rotation_mean"] = None if tr is None else tr["mean"] <= 0.00252
    checks["half_paper_rotation_mae"] = None if rot is None else rot["mean"] <= 0.789
    return checks


def _fmt(x: float | None, unit: str = "") -> str:
    if x is None:
        return "-"
    if unit == "deg":
        return f"{x:.3f}"
    return f"{x:.2e}" if abs(x) < 1e-3 and x != 0 else f"{x:.4f}"


def markdown_report(result: dict[str, Any]) -> str:
    """The paper's Tables 1 and 2 beside ours, then every route and method."""
    cfg = result["config"]
    routes = {r["name"]: r for r in result["routes"]}
    lines = [
        "## Closed-loop tracking vs the paper",
        "",
        f"Repeat with actuation noise {cfg['noise']} (simulator level: a per-run bias of {cfg['noise']:.0%} in speed scale and "
        f"{0.5 * cfg['noise']:.3f} rad/m of curvature drift, plus {cfg['noise']:.0%} per-step jitter, 1 sigma each), "
        f"from the taught start. e_m: {'calibrated per route' if cfg['e_m'] is None else cfg['e_m']}.",
        "",
    ]
    methods = [m for m in ("velocitynet", "velocitynet_int8", "ablation_w2_0", "online_mpc", "open_loop", "pose_oracle")
               if any(m in r["scenarios"].get("noise", {}) for r in routes.values())]  # fmt: skip
    for title, names, unit in (
        ("Table 1: nearest-point position error (m)", ("translation", "translation_rotation"), "m"),
        ("Table 2: nearest yaw error, pure rotation (deg)", ("rotation",), "deg"),
    ):
        present = [n for n in names if n in routes]
        if not present:
            continue
        lines += [f"### {title}", ""]
        header = "| statistic |"
        sep = "|---|"
        for n in present:
            header += f" paper {n} |" + "".join(f" {m} {n} |" for m in methods)
            sep += "---|" * (1 + len(methods))
        lines += [header, sep]
        for stat in ("min", "max", "mean", "std"):
            label = "MAE" if (stat == "mean" and unit == "deg") else stat
            row = f"| {label} |"
            for n in present:
                row += f" {_fmt(PAPER[n][stat], unit)} |"
                for m in methods:
                    s = _paper_stat(routes[n], m)
                    row += f" {_fmt(None if s is None else s[stat], unit)} |"
            lines.append(row)
        lines.append("")
    for scen in ("noise", "offset"):
        if not any(scen in r["scenarios"] for r in routes.values()):
            continue
        what = (
            f"actuation noise {cfg['noise']}"
            if scen == "noise"
            else f"start offset dx={cfg['offset'][0]} m, dy={cfg['offset'][1]} m, dyaw={cfg['offset'][2]} deg, no noise"
        )
        lines += [
            f"### Every route: {what}",
            "",
            "| route | method | done | completion | mean err (m) | max err (m) | yaw MAE (deg) | cross-track (m) "
            "| final (m) | steps | sim time (s) | mean abs dv | mean abs dw | policy ms |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for name, r in routes.items():
            for m, run in r["scenarios"].get(scen, {}).items():
                pm = run.get("policy_ms", {}).get("p50")
                lines.append(
                    f"| {name} | {m} | {'yes' if run['completed'] else 'no'} | {run['completion']:.0%} "
                    f"| {_fmt(run['position_error_m']['mean'])} | {_fmt(run['position_error_m']['max'])} "
                    f"| {run['yaw_error_deg']['mean']:.3f} | {_fmt(run['mean_cross_track_error_m'])} "
                    f"| {_fmt(run['final_pose_error']['position_m'])} | {run['steps']} | {run['sim_time_s']:.1f} "
                    f"| {run['smoothness']['mean_abs_dv']:.4f} | {run['smoothness']['mean_abs_dw']:.4f} "
                    f"| {'-' if pm is None else f'{pm:.2f}'} |"
                )
        lines.append("")
    agg = result["aggregate"]
    lines += ["### Aggregate", "", "| scenario | method | completed | mean err (m) | cross-track (m) | policy ms p50 |",
              "|---|---|---|---|---|---|"]  # fmt: skip
    for scen, by_method in agg.items():
        for m, a in by_method.items():
            pm = a["policy_ms_p50"]
            lines.append(
                f"| {scen} | {m} | {a['completed']}/{a['routes']} | {_fmt(a['mean_position_error_m'])} "
                f"| {_fmt(a['mean_cross_track_error_m'])} | {'-' if pm is None else f'{pm:.2f}'} |"
            )
    if result.get("notes"):
        lines += ["", "Not run: " + "; ".join(result["notes"]) + "."]
    lines += ["", "### Bar (issue 5)", ""]
    for key, ok in result["bar"].items():
        lines.append(f"- {key}: {'-' if ok is None else ('met' if ok else 'MISSED')}")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- plots


def draw_house(ax: Any) -> bool:
    """Draw the house top-down on a matplotlib axis: walls dark, furniture light, room names.

    Returns False (and draws nothing) when the simulator's house cannot be loaded: a plot without a floor
    plan is still a plot.
    """
    try:
        from vtr.sim2d import load_house

        house = load_house()
        seg = house.segments
        walls = np.asarray(seg.is_wall, dtype=bool)
        a, b = np.asarray(seg.a), np.asarray(seg.b)
    except Exception:
        return False
    for mask, colour, width in ((~walls, "0.7", 0.8), (walls, "0.25", 1.6)):
        for p, q in zip(a[mask], b[mask], strict=True):
            ax.plot([p[0], q[0]], [p[1], q[1]], color=colour, lw=width, zorder=1)
    for room in house.rooms:
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
    colours = {"velocitynet": "tab:red", "velocitynet_int8": "tab:orange", "ablation_w2_0": "tab:purple",
               "online_mpc": "tab:green", "open_loop": "tab:gray", "pose_oracle": "tab:olive"}  # fmt: skip
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
        written.append(_save(fig, out_dir / f"{r['name']}_path.png"))

        rotation = r["name"] == "rotation" or any(run["rotation_only"] for run in runs.values())
        fig, ax = plt.subplots(figsize=(7, 3.5))
        for m, run in runs.items():
            err = run["per_subgoal_yaw_error_deg" if rotation else "per_subgoal_position_error_m"]
            ax.plot(np.arange(len(err)), err, ".-", ms=3, lw=0.8, color=colours.get(m, "k"), label=m)
        ax.set_xlabel("subgoal index")
        ax.set_ylabel("yaw error (deg)" if rotation else "position error (m)")
        ax.set_title(f"{r['name']}: nearest-point error per subgoal")
        ax.legend(fontsize=7)
        written.append(_save(fig, out_dir / f"{r['name']}_error.png"))

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
            written.append(_save(fig, out_dir / f"{r['name']}_yaw.png"))
    return written


def frame_route(ax: Any, taught: np.ndarray, margin: float = 1.0) -> None:
    """Zoom on the route with a margin of house around it (at least 3 m wide, equal axes)."""
    lo, hi = taught[:, :2].min(axis=0) - margin, taught[:, :2].max(axis=0) + margin
    centre, half = (lo + hi) / 2, max(1.5, *(hi - lo) / 2)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_aspect("equal", adjustable="box")


def _save(fig: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


# ---------------------------------------------------------------- entry points


def run(cfg: EvalConfig) -> dict[str, Any]:
    """Evaluate every route (in a process pool when workers > 1) and write JSON, Markdown and plots."""
    names = cfg.routes or (QUICK_ROUTES if cfg.quick else ())
    files = route_files(names)
    t0 = time.perf_counter()
    if cfg.workers > 1 and len(files) > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        # spawn: a fresh interpreter per worker, no forked onnxruntime or torch thread pools.
        with ProcessPoolExecutor(
            max_workers=min(cfg.workers, len(files)), mp_context=mp.get_context("spawn")
        ) as ex:
            routes = list(ex.map(evaluate_route, files, [cfg] * len(files)))
    else:
        routes = [evaluate_route(f, cfg) for f in files]
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
        from vtr.benchmarks.latency import write_json

        write_json(Path(cfg.json_path), result)
    if cfg.markdown_path is not None:
        write_text_atomic(cfg.markdown_path, markdown_report(result))
    return result


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--model", type=Path, default=Path("models/velocitynet.onnx"), help="fp32 VelocityNet ONNX"
    )
    parser.add_argument(
        "--json", type=Path, default=None, help="write every number here (and a .md table beside)"
    )
    parser.add_argument("--plots", type=Path, default=None, help="folder for the PNG plots")
    parser.add_argument(
        "--routes", nargs="*", default=[], help="route names or ROUTE.json paths (default: all)"
    )
    parser.add_argument("--noise", type=float, default=0.05, help="actuation noise level of the repeat runs")
    parser.add_argument("--offset", type=float, nargs=3, default=[0.03, 0.03, 3.0], metavar=("DX", "DY", "DYAW"),
                        help="start offset for the offset scenario: m, m (robot frame), deg")  # fmt: skip
    parser.add_argument(
        "--int8-model", type=Path, default=None, help="int8 twin (default: <model>-int8.onnx)"
    )
    parser.add_argument(
        "--ablation-model", type=Path, default=None, help="VelocityNet trained with w2 = 0 (ONNX)"
    )
    parser.add_argument(
        "--viewnet", type=Path, default=None, help="ViewNet checkpoint: enables the online MPC"
    )
    parser.add_argument("--mpc-routes", nargs="*", default=list(PAPER_ROUTES), help="routes the MPC runs on")
    parser.add_argument("--mpc-samples", type=int, default=32, help="candidate sequences per MPC step")
    parser.add_argument("--no-open-loop", action="store_true", help="skip the open-loop replay baseline")
    parser.add_argument("--oracle", action="store_true", help="add the pose-oracle diagnostic (not visual)")
    parser.add_argument("--e-m", type=float, default=None, help="fixed e_m (paper: 17); default calibrated")
    parser.add_argument("--seed", type=int, default=0, help="actuation noise seed")
    parser.add_argument("--threads", type=int, default=1, help="inference threads per worker")
    parser.add_argument("--workers", type=int, default=2, help="processes over routes")
    parser.add_argument("--quick", action="store_true", help="one short route, noise scenario only, no MPC")
    parser.add_argument("--run", type=Path, default=None, help="score a run recorded by `vtr repeat --mcap`")
    parser.add_argument(
        "--taught", type=Path, default=None, help="--run: the taught route (.npz) it repeated"
    )


def config_from_args(args: argparse.Namespace) -> EvalConfig:
    return EvalConfig(
        model=args.model,
        routes=tuple(args.routes),
        noise=args.noise,
        offset=tuple(args.offset),
        int8_model=args.int8_model,
        ablation_model=args.ablation_model,
        viewnet=args.viewnet,
        mpc_routes=tuple(args.mpc_routes),
        mpc_samples=args.mpc_samples,
        open_loop=not args.no_open_loop,
        oracle=args.oracle,
        e_m=args.e_m,
        seed=args.seed,
        threads=args.threads,
        workers=1 if args.quick else args.workers,
        quick=args.quick,
        json_path=args.json,
        plots_dir=args.plots,
    )


def run_cli(args: argparse.Namespace) -> int:
    if args.run is not None:  # a recorded run from any robot instead of simulated runs
        from vtr.benchmarks.recorded_runs import run_cli as score_run_cli

        return score_run_cli(args)
    try:
        cfg = config_from_args(args)
    except ValueError as err:
        print(f"vtr eval: {err}", file=sys.stderr)
        return 2
    result = run(cfg)
    print(markdown_report(result))
    for path in (cfg.json_path, cfg.markdown_path, cfg.plots_dir):
        if path is not None:
            print(f"wrote {path}")
    return 0
