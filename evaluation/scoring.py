"""Scoring: every metric of one run, aggregates over routes, and the bar the results are judged by."""

from __future__ import annotations

from typing import Any

import numpy as np

from vtr.evaluation import metrics
from vtr.evaluation.runs import RunLog

#: The paper's three scenarios (route file stems) and its Tables 1 and 2.
PAPER_ROUTES = ("translation", "rotation", "translation_rotation")
PAPER = {
    "translation": {"unit": "m", "min": 3.37e-6, "max": 0.025, "mean": 0.012, "std": 6.98e-3},
    "translation_rotation": {"unit": "m", "min": 2.13e-4, "max": 8.825e-3, "mean": 5.04e-3, "std": 2.203e-3},
    "rotation": {"unit": "deg", "min": 6.36e-3, "max": 5.053, "mean": 1.578, "std": 1.187},
}


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
        out["policy_ms"] = {
            "p50": float(np.percentile(ms, 50)),
            "p99": float(np.percentile(ms, 99)),
            "mean": float(ms.mean()),
        }
    # each commanded step's compute (judgement, policy, limits; the link and simulator apart)
    if log.compute_ms:
        p50, p99 = np.percentile(log.compute_ms, [50, 99])
        out["step_compute_ms"] = {
            "p50": round(float(p50), 4),
            "p99": round(float(p99), 4),
            "max": round(max(log.compute_ms), 4),
        }
    return out


def paper_stat(route_result: dict[str, Any], method: str, scenario: str = "noise") -> dict[str, float] | None:
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
        return paper_stat(by_name[name], "velocitynet") if name in by_name else None

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
            fp, q = paper_stat(by_name[name], "velocitynet"), paper_stat(by_name[name], "velocitynet_int8")
            if fp is not None and q is not None:
                ratios.append(q["mean"] / max(fp["mean"], 1e-12))
    checks["int8_within_10pct_of_fp32"] = bool(max(ratios) <= 1.10) if ratios else None
    # the stretch goal: half the paper's errors
    checks["half_paper_translation_mean"] = None if t is None else t["mean"] <= 0.006
    checks["half_paper_translation_rotation_mean"] = None if tr is None else tr["mean"] <= 0.00252
    checks["half_paper_rotation_mae"] = None if rot is None else rot["mean"] <= 0.789
    return checks
