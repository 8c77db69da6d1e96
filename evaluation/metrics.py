"""Tracking metrics for teach & repeat runs: pure numpy functions over poses and commands.

The paper scores a repeat run by, for each taught pose, the nearest repeated pose (Eq. error(x, y)) and,
for pure rotation, the nearest repeated yaw (Eq. error(psi)). Both are reported as min / max / mean / std,
with the population standard deviation (ddof=0). The other metrics here are our additions: completion,
final pose error, mean cross-track error to the taught polyline, and command smoothness.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def _as_xy(points: np.ndarray | Sequence[Sequence[float]], what: str) -> np.ndarray:
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] < 2:
        raise ValueError(f"{what} must be an (n, 2) array of x, y points, got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError(f"{what} is empty")
    return arr[:, :2]


#: A completed run that passed some taught subgoal farther than this (m) finished another path: the tables
#: count such runs beside "completed" (a re-coloured floor "completes" routes 0.1-0.9 m beside the taught one).
OFF_PATH_M = 0.10


#: A finished run counts as completed only on the route: its mean nearest-point error at most ON_ROUTE_MEAN_M
#: and its final position within ON_ROUTE_FINAL_M of the taught end (issue 19: runs that "finished" 10 cm
#: beside the route were counted as successes).
ON_ROUTE_MEAN_M, ON_ROUTE_FINAL_M = 0.03, 0.05


def off_route(mean_error_m: float, final_error_m: float) -> str:
    """Why a finished run is not on the route ("" when it is)."""
    why = []
    if not mean_error_m <= ON_ROUTE_MEAN_M:
        why.append(f"mean error {mean_error_m * 1e3:.0f} mm > {ON_ROUTE_MEAN_M * 1e3:.0f}")
    if not final_error_m <= ON_ROUTE_FINAL_M:
        why.append(f"final position {final_error_m * 1e3:.0f} mm > {ON_ROUTE_FINAL_M * 1e3:.0f} from the end")
    return ", ".join(why)


def off_path(runs: Sequence[dict]) -> int:
    """How many of these completed runs' largest nearest-point error exceeds OFF_PATH_M."""
    return sum(
        1
        for r in runs
        if r.get("max_position_error_m") is not None and r["max_position_error_m"] > OFF_PATH_M
    )


def wrap_angle(angle: np.ndarray | float) -> np.ndarray:
    """Wrap angles (rad) to [-pi, pi)."""
    return (np.asarray(angle, dtype=np.float64) + math.pi) % (2.0 * math.pi) - math.pi


def densify_path(poses: np.ndarray, per_step: int) -> np.ndarray:
    """Insert per_step - 1 poses between consecutive (x, y, yaw) poses by linear interpolation (yaw wrapped).

    The robot drives continuously between the poses sampled at each control step; the paper's
    nearest-point error is taken against its real-time trajectory, so scoring only the step endpoints would
    add a sampling error of up to half a step's travel. Over one 0.1 s step (at most 5 cm, 0.1 rad) the
    straight chord is within a millimetre of the arc actually driven.
    """
    arr = np.asarray(poses, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"poses must be (n, 3), got {arr.shape}")
    if per_step < 1:
        raise ValueError(f"per_step must be >= 1, got {per_step}")
    if per_step == 1 or arr.shape[0] < 2:
        return arr.copy()
    t = np.arange(per_step, dtype=np.float64) / per_step  # (k,)
    start, delta = arr[:-1], np.diff(arr, axis=0)  # (n-1, 3)
    delta[:, 2] = wrap_angle(delta[:, 2])
    inner = start[:, None, :] + t[None, :, None] * delta[:, None, :]  # (n-1, k, 3)
    out = np.concatenate([inner.reshape(-1, 3), arr[-1:]], axis=0)
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def nearest_point_errors(taught_xy: np.ndarray, repeated_xy: np.ndarray) -> np.ndarray:
    """For each taught (x, y), the distance (m) to the nearest repeated (x, y): shape (len(taught),)."""
    taught = _as_xy(taught_xy, "taught_xy")
    repeated = _as_xy(repeated_xy, "repeated_xy")
    diff = taught[:, None, :] - repeated[None, :, :]  # (T, R, 2)
    return np.sqrt((diff**2).sum(axis=-1)).min(axis=1)


def nearest_yaw_errors(taught_yaw: np.ndarray, repeated_yaw: np.ndarray) -> np.ndarray:
    """For each taught yaw, the wrapped angular distance (deg) to the nearest repeated yaw."""
    taught = np.asarray(taught_yaw, dtype=np.float64).ravel()
    repeated = np.asarray(repeated_yaw, dtype=np.float64).ravel()
    if taught.size == 0 or repeated.size == 0:
        raise ValueError(
            f"yaw sequences must be non-empty, got {taught.size} taught and {repeated.size} repeated"
        )
    diff = np.abs(wrap_angle(taught[:, None] - repeated[None, :]))  # (T, R)
    return np.degrees(diff.min(axis=1))


def error_stats(errors: np.ndarray) -> dict[str, float]:
    """min / max / mean / std (population) of a non-empty error vector; `mean` doubles as the MAE."""
    arr = np.asarray(errors, dtype=np.float64).ravel()
    if arr.size == 0:
        raise ValueError("no errors to summarise")
    return {
        "min": float(arr.min()),
        "max": float(arr.max()),
        "mean": float(arr.mean()),
        "std": float(arr.std()),
        "n": int(arr.size),
    }


def completion(subgoals_reached: int, subgoals_total: int) -> float:
    """Fraction of the taught subgoals the repeat run reached, in [0, 1]."""
    if subgoals_total <= 0:
        raise ValueError(f"subgoals_total must be positive, got {subgoals_total}")
    if not 0 <= subgoals_reached <= subgoals_total:
        raise ValueError(f"subgoals_reached must be in [0, {subgoals_total}], got {subgoals_reached}")
    return subgoals_reached / subgoals_total


def final_pose_error(taught_final: Sequence[float], repeated_final: Sequence[float]) -> dict[str, float]:
    """Distance (m) and absolute wrapped yaw difference (deg) between the last taught and last repeated pose.

    Poses are (x, y, yaw) with yaw in radians.
    """
    if len(taught_final) != 3 or len(repeated_final) != 3:
        raise ValueError(f"poses must be (x, y, yaw), got {taught_final!r} and {repeated_final!r}")
    dx = repeated_final[0] - taught_final[0]
    dy = repeated_final[1] - taught_final[1]
    dyaw = float(abs(wrap_angle(repeated_final[2] - taught_final[2])))
    return {"position_m": math.hypot(dx, dy), "yaw_deg": math.degrees(dyaw)}


def point_to_polyline_distances(points_xy: np.ndarray, polyline_xy: np.ndarray) -> np.ndarray:
    """Distance (m) from each point to the nearest segment of the polyline (a single point if length 1)."""
    points = _as_xy(points_xy, "points_xy")
    line = _as_xy(polyline_xy, "polyline_xy")
    if line.shape[0] == 1:
        return np.sqrt(((points - line[0]) ** 2).sum(axis=1))
    a = line[:-1]  # (S, 2) segment starts
    ab = line[1:] - a  # (S, 2)
    length2 = (ab**2).sum(axis=1)  # (S,)
    ap = points[:, None, :] - a[None, :, :]  # (P, S, 2)
    # Degenerate (zero-length) segments project onto their start point.
    t = np.where(length2 > 0, (ap * ab[None]).sum(axis=-1) / np.where(length2 > 0, length2, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)  # (P, S)
    closest = a[None] + t[..., None] * ab[None]  # (P, S, 2)
    return np.sqrt(((points[:, None, :] - closest) ** 2).sum(axis=-1)).min(axis=1)


def mean_cross_track_error(repeated_xy: np.ndarray, taught_xy: np.ndarray) -> float:
    """Mean distance (m) from the repeated positions to the taught path as a polyline."""
    return float(point_to_polyline_distances(repeated_xy, taught_xy).mean())


def smoothness(commands: np.ndarray) -> dict[str, float]:
    """Mean |dv| (m/s) and |dw| (rad/s) between consecutive commands; commands is (K, 2) of (v, w).

    Fewer than two commands give zeros: nothing changed.
    """
    cmds = np.asarray(commands, dtype=np.float64)
    if cmds.ndim != 2 or cmds.shape[1] != 2:
        raise ValueError(f"commands must be a (K, 2) array of (v, w), got shape {cmds.shape}")
    if cmds.shape[0] < 2:
        return {"mean_abs_dv": 0.0, "mean_abs_dw": 0.0}
    d = np.abs(np.diff(cmds, axis=0))
    return {"mean_abs_dv": float(d[:, 0].mean()), "mean_abs_dw": float(d[:, 1].mean())}


def is_rotation_route(taught_poses: np.ndarray, max_translation_m: float = 0.05) -> bool:
    """True when the taught route barely moves (the paper scores such routes by yaw)."""
    poses = np.asarray(taught_poses, dtype=np.float64)
    xy = poses[:, :2]
    return bool(np.sqrt(((xy - xy[0]) ** 2).sum(axis=1)).max() <= max_translation_m)


def route_metrics(
    taught_poses: np.ndarray,
    repeated_poses: np.ndarray,
    commands: np.ndarray,
    subgoals_reached: int,
    per_step: int = 10,
) -> dict[str, object]:
    """All metrics of one repeat run.

    Args:
        taught_poses: (T, 3) poses (x, y, yaw) of the taught subgoals, in order.
        repeated_poses: (R, 3) poses at each control step of the repeat (at least the start pose).
        commands: (K, 2) commands (v, w) the controller sent, in order.
        subgoals_reached: how many subgoals the controller passed.
        per_step: the repeated path is densified to this many poses per control step (see densify_path)
            for the path errors and the cross-track error.

    The paper's errors (``position_error_m``, ``yaw_error_deg``) take the repeated poses as sampled at
    each velocity command, as its figures do ("real-time robot coordinates upon receiving generated
    velocity commands"); ``path_*`` take the continuous path, which also credits the robot for passing
    through a taught pose between two commands.
    """
    taught = np.asarray(taught_poses, dtype=np.float64)
    repeated = np.asarray(repeated_poses, dtype=np.float64)
    if taught.ndim != 2 or taught.shape[1] != 3 or repeated.ndim != 2 or repeated.shape[1] != 3:
        raise ValueError(f"poses must be (n, 3) arrays, got {taught.shape} and {repeated.shape}")
    dense = densify_path(repeated, per_step)
    per_subgoal_m = nearest_point_errors(taught[:, :2], repeated[:, :2])
    per_subgoal_deg = nearest_yaw_errors(taught[:, 2], repeated[:, 2])
    return {
        "position_error_m": error_stats(per_subgoal_m),
        "yaw_error_deg": error_stats(per_subgoal_deg),
        "path_position_error_m": error_stats(nearest_point_errors(taught[:, :2], dense[:, :2])),
        "path_yaw_error_deg": error_stats(nearest_yaw_errors(taught[:, 2], dense[:, 2])),
        "path_samples_per_step": per_step,
        "per_subgoal_position_error_m": per_subgoal_m.tolist(),
        "per_subgoal_yaw_error_deg": per_subgoal_deg.tolist(),
        "completion": completion(subgoals_reached, taught.shape[0]),
        "completed": subgoals_reached == taught.shape[0],
        "final_pose_error": final_pose_error(tuple(taught[-1]), tuple(repeated[-1])),
        "mean_cross_track_error_m": mean_cross_track_error(dense[:, :2], taught[:, :2]),
        "smoothness": smoothness(commands if len(commands) else np.zeros((0, 2))),
        "rotation_only": is_rotation_route(taught),
    }
