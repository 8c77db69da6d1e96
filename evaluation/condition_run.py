"""One repeat of a taught route under a changed condition, with one controller: what the condition-suite
(evaluation.condition_suite), the held-out houses (evaluation.house_suite) and evaluation.trace_run run.

``CONDITIONS`` names what differs at repeat time (actuation noise, a start offset, repeat-time lighting, a
changed room); ``CONTROLLERS`` names how the runtime repeats (the paper's Algorithm 1, the previous default,
the current one and its ablations). ``run_once`` repeats once and scores the run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from vtr.evaluation.conditions import BLOCKING_SCENES, LIGHTING, MOVING_SCENES, PATH_SCENES, SCENES
from vtr.evaluation.metrics import off_route
from vtr.evaluation.path_boxes import box_distance
from vtr.evaluation.sensor_conditions import SENSORS
from vtr.runtime.controller import ControllerConfig
from vtr.runtime.matching import MatchConfig

#: What a run under a condition should do: finish on the route, or stop before what blocks it.
EXPECTATIONS = ("finished", "blocked")


@dataclass(frozen=True)
class Condition:
    """What differs at repeat time: actuation noise, start offset (lateral m, yaw deg; its sign flips
    with odd seeds), the light on the camera image (a LIGHTING key) and the house (a SCENES key); what the
    run should do (``expect``, one of EXPECTATIONS); ``clear_after_s``: the path scene's box is taken away
    once the robot has stood that long (conditions.ClearingRobot), None: it stays."""

    noise: float = 0.05
    offset: tuple[float, float] = (0.0, 0.0)
    light: str | None = None
    scene: str | None = None
    expect: str = "finished"
    clear_after_s: float | None = None
    camera: tuple[float, float] | None = None  # (fov deg, height m) of teach and repeat; None: the default
    sensor: str | None = None  # a sensor_conditions.SENSORS key: the repeat's camera sensor realism

    def __post_init__(self) -> None:
        if self.expect not in EXPECTATIONS:
            raise ValueError(f"expect must be one of {EXPECTATIONS}, got {self.expect!r}")


CONDITIONS: dict[str, Condition] = {
    "noise_0.05": Condition(),
    "noise_0.10": Condition(noise=0.10),
    "offset_5cm_5deg": Condition(offset=(0.05, 5.0)),
    "offset_10cm_10deg": Condition(offset=(0.10, 10.0)),
    **{name: Condition(light=name) for name in LIGHTING},
    **{name: Condition(scene=name) for name in (*SCENES, *PATH_SCENES) if name not in BLOCKING_SCENES},
    **{name: Condition(sensor=name) for name in SENSORS},
    # a box on the taught path half-way along: stop before it (status blocked, no contact) ...
    "box_on_path": Condition(scene="box_on_path", expect="blocked"),
    # ... and one just past a taught turn in place: first seen as the turn ends
    "box_after_turn": Condition(scene="box_after_turn", expect="blocked"),
    # ... and, taken away after the robot has waited 2 s in front of it, resume and finish
    "box_removed": Condition(scene="box_on_path", clear_after_s=2.0),
}


def judged(expect: str, outcome: str, detail: str, touched: bool, beside: str) -> tuple[bool, str]:
    """Whether a run did what its condition expects (the suite's "completed"), and if not, why.

    "finished": the repeat finished on the route (``beside`` empty: see metrics.off_route) without
    touching anything; "blocked": it stopped as blocked without touching anything."""
    if outcome == expect == "blocked":
        return (False, "blocked after a contact") if touched else (True, "")
    if outcome == expect == "finished":
        if touched:
            return False, "finished but touched furniture"
        return (False, f"finished off the route: {beside}") if beside else (True, "")
    if outcome == "finished":  # expected blocked: it drove past (or through) what was in the way
        return False, "finished past the box" if not touched else "finished but touched furniture"
    return False, f"{outcome}: {detail}" if detail else outcome


@dataclass(frozen=True)
class Method:
    """How the runtime repeats: the controller's settings, and whether the current image is recoloured to
    the subgoal's light before the policy sees it (runtime.light), and whether the robot has a range scanner
    (its scan feeds runtime.safety's stop and slowdown zones)."""

    controller: ControllerConfig
    match_light: bool = False
    side_ramp: bool = True  # with match_light: also even out a left-to-right gain
    scan: bool = False


AFTER = ControllerConfig()  # the route localiser and the follower, patch matching, zero bias, turns held
CONTROLLERS: dict[str, Method] = {
    "paper": Method(ControllerConfig.paper()),  # Algorithm 1: raw error, e_m = 17
    "before": Method(ControllerConfig.before()),  # the previous default: raw error, one e_m per route
    "after": Method(AFTER, match_light=True),
    "after_scan": Method(AFTER, match_light=True, scan=True),  # the same robot with a range scanner
    # the camera-only obstruction stop off (runtime.obstruction): what the issue found
    "after_no_obstruction": Method(replace(AFTER, obstruction=False), match_light=True),
    # the range scan alone (its stop distance, with no camera stop before it)
    "after_scan_only": Method(replace(AFTER, obstruction=False), match_light=True, scan=True),
    # the release before the route localiser: threshold switching, plateau, stall guard, progress gate
    "rules": Method(replace(AFTER, switching="rules"), match_light=True),
    # no turn toward the path from the floor's side offset (runtime.side_offset): VelocityNet alone beside it
    "after_no_side": Method(replace(AFTER, side_gain=0.0), match_light=True),
    "after_ff_0": Method(replace(AFTER, feed_forward=0.0), match_light=True),
    "after_ff_0.8": Method(replace(AFTER, feed_forward=0.8), match_light=True),
    "after_lead_1": Method(replace(AFTER, lead=1.0), match_light=True),
    "after_ff_turn_0": Method(replace(AFTER, feed_forward_turn=0.0), match_light=True),
    "after_lead_0.75": Method(replace(AFTER, lead=0.75), match_light=True),
    "after_lead_0.75_ff_turn_0": Method(replace(AFTER, lead=0.75, feed_forward_turn=0.0), match_light=True),
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


_POLICIES: dict[tuple[str, int], Any] = {}  # per worker process: ONNX sessions by (path, threads)


def cached_policy(path: Path, threads: int) -> Any:
    """One OnnxPolicy per (model, threads) in this process."""
    from vtr.runtime.policy import OnnxPolicy

    key = (str(path), threads)
    if key not in _POLICIES:
        _POLICIES[key] = OnnxPolicy(path, threads=threads)
    return _POLICIES[key]


def start_pose(pose: np.ndarray, offset: tuple[float, float], seed: int) -> tuple[float, float, float]:
    x, y, yaw = (float(v) for v in pose)
    sign = 1.0 if seed % 2 == 0 else -1.0
    lateral, dyaw = sign * offset[0], sign * math.radians(offset[1])
    return (x - math.sin(yaw) * lateral, y + math.cos(yaw) * lateral, yaw + dyaw)


def step_compute_summary(runs: list[dict[str, Any]]) -> dict[str, float] | None:
    """Over runs (each with ``scoring.score``'s ``step_compute_ms``): the median of their step compute p50 and p99, the largest p99 and the steps' largest (ms)."""
    timed = [r["step_compute_ms"] for r in runs if r.get("step_compute_ms")]
    if not timed:
        return None
    return {
        "runs": len(timed),
        "p50": float(np.median([t["p50"] for t in timed])),
        "p99": float(np.median([t["p99"] for t in timed])),
        "worst_p99": max(t["p99"] for t in timed),
        "max": max(t["max"] for t in timed),
    }


def step_compute_line(summary: dict[str, float] | None, workers: int) -> str:
    """The tables' line on the real step's cost (``step_compute_summary``)."""
    if summary is None:
        return "Step compute: no run commanded a step."
    return (
        f"Step compute (the runtime's judgement, policy and limits of each commanded step; the simulator and the "
        f"link apart; this machine, {workers} worker(s) at once): per run p50 {summary['p50']:.2f} ms and p99 "
        f"{summary['p99']:.2f} ms (medians over {summary['runs']} runs); worst run's p99 "
        f"{summary['worst_p99']:.2f} ms, slowest step {summary['max']:.2f} ms."
    )


def switch_lag(taught: np.ndarray, switch_poses: dict[int, tuple[float, float, float]]) -> float | None:
    """Mean along-track offset (m) of the robot from each subgoal's taught pose when the controller
    switched past it: negative = the robot was still short of the subgoal (the index ran ahead)."""
    if not switch_poses:
        return None
    k = np.fromiter(switch_poses, dtype=int)
    at = np.asarray([switch_poses[i] for i in k], dtype=np.float64)
    p = np.asarray(taught, dtype=np.float64)[k]
    return float(np.mean((at[:, 0] - p[:, 0]) * np.cos(p[:, 2]) + (at[:, 1] - p[:, 1]) * np.sin(p[:, 2])))


def suite_robot(route: Any, cond: Condition, house: str, method: Method, dt: float) -> tuple[Any, Any, Any]:
    """The robot a suite run under ``cond`` repeats ``route`` on, in ``house`` (the condition's scene already
    written): the simulator with the condition's camera, sensor and noise, wrapped to take the path's box
    away (``clear_after_s``), to move it across the path (a moving scene) and to change the light. Returns
    (robot, clearing, crossing): the last two those wrappers, None where the condition has none. One place,
    so that ``run_once`` and ``evaluation.trace_run`` repeat on the same robot."""
    from vtr.evaluation.conditions import LitRobot
    from vtr.evaluation.moving_box import CrossingRobot
    from vtr.evaluation.path_boxes import ClearingRobot, path_box, write_cleared_house
    from vtr.sim2d import SimConfig, Simulator
    from vtr.sim2d.config import camera_config
    from vtr.sim2d.local_robot import LocalRobot

    h, w = route.images.shape[1:3]
    sim = Simulator(
        SimConfig(
            camera=camera_config(w, h, cond.camera),
            sensor=SENSORS.get(cond.sensor or ""),
            noise=cond.noise,
            house=house,
        )
    )
    robot: Any = LocalRobot(sim, scan=method.scan)
    clearing = crossing = None
    if cond.clear_after_s is not None:
        clearing = robot = ClearingRobot(robot, str(write_cleared_house(house)), cond.clear_after_s, dt)
    if cond.scene in MOVING_SCENES:
        crossing = robot = CrossingRobot(robot, path_box(house) or {})
    if cond.light:
        robot = LitRobot(robot, LIGHTING[cond.light])
    return robot, clearing, crossing


def run_once(
    route: Any,
    script: Any,
    cond: Condition,
    house: str,
    seed: int,
    method: Method,
    policy: Any,
    cfg: Any,
    keep_path: bool = False,
) -> dict[str, Any]:
    """One repeat under ``cond`` (evaluation.runs, the `vtr eval` harness's loop); its scores plus the
    status, whether it did what the condition expects (``completed``, see :func:`judged`) and if not why,
    and the control steps per taught control step (``keep_path``: and the repeated x, y in mm precision);
    with the path box: ``box_face_m``, and ``cleared_at_s`` (simulated time it was taken away, None if
    never). ``cfg`` needs dt and max_steps_factor (a SuiteConfig)."""
    from vtr.evaluation.path_boxes import path_box
    from vtr.evaluation.runs import repeat_closed_loop
    from vtr.evaluation.scoring import score
    from vtr.runtime.light import LightMatchedPolicy

    robot, clearing, crossing = suite_robot(route, cond, house, method, cfg.dt)
    if method.match_light:
        policy = LightMatchedPolicy(policy, side_ramp=method.side_ramp)
    start = start_pose(route.poses[0], cond.offset, seed)
    try:
        log = repeat_closed_loop(robot, policy, route, start, cfg, seed, controller_cfg=method.controller)
    except ValueError as err:
        if "not free space" not in str(err):
            raise
        return {"status": "start_blocked", "cause": str(err), "completed": False, "ran": False}
    s = score(route, log)
    touched = log.collisions > 0
    beside = off_route(s["position_error_m"]["mean"], s["final_pose_error"]["position_m"])
    completed, cause = judged(cond.expect, log.outcome, log.detail, touched, beside)
    box = path_box(house)
    extra: dict[str, Any] = {}
    if box is not None and cond.scene in BLOCKING_SCENES:  # where the robot ended: its centre to the box's
        extra["box_face_m"] = box_distance(box, *log.poses[-1][:2])  # nearest face (contact at its radius)
    if box is not None and clearing is None:  # how near it came to the box (taken away: it drives through)
        extra["box_closest_m"] = min(box_distance(box, *p[:2]) for p in log.poses)
    if crossing is not None:  # the box moved: where it was at each step
        extra["box_closest_m"], extra["box_started_at_s"] = crossing.closest, crossing.started_at
    if clearing is not None:
        extra["cleared_at_s"] = clearing.cleared_at
    return {
        "ran": True,
        "status": log.outcome,
        "completed": completed,
        "cause": cause,
        "on_route": not beside,  # metrics.off_route: mean nearest-point error and final position in bounds
        **extra,
        "contacts": log.collisions,
        "waited_steps": log.waited_steps,  # held still for something in the way (ended or not)
        "detail": log.detail,
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
        "step_compute_ms": s.get("step_compute_ms"),  # p50, p99, largest (scoring.score); None: no command
        **({"path": np.round(np.asarray(log.poses)[:, :2], 3).tolist()} if keep_path else {}),
    }
