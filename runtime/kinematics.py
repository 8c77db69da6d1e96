"""The unicycle the protocol's (v, w) commands drive: one source for the arc a held command traces, and for
the motion a taught route makes between its subgoals."""

from __future__ import annotations

import math
from typing import TypeVar

import numpy as np

AngleT = TypeVar("AngleT", float, np.ndarray)


def wrap_angle(angle: AngleT) -> AngleT:
    """``angle`` (rad; a number or an array) wrapped to [-pi, pi): the turn between two headings."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def unicycle(x: float, y: float, yaw: float, v: float, w: float, t: float) -> tuple[float, float, float]:
    """The pose after holding (v, w) for ``t`` seconds from (x, y, yaw): a straight line or an exact arc."""
    if abs(w) < 1e-6:
        return x + v * t * math.cos(yaw), y + v * t * math.sin(yaw), yaw
    r = v / w
    return (
        x + r * (math.sin(yaw + w * t) - math.sin(yaw)),
        y - r * (math.cos(yaw + w * t) - math.cos(yaw)),
        yaw + w * t,
    )


def taught_motion(travel_poses: np.ndarray | None, commands: np.ndarray, n: int, steps: float) -> np.ndarray:
    """(n-1, 2) signed taught motion of each gap: (metres forward, radians counter-clockwise).

    From the taught poses where known (the sign of the distance from the taught command); else the taught
    command held for ``steps`` control steps of its dt (the caller passes ``dt * steps`` as ``steps``)."""
    out = np.zeros((max(n - 1, 0), 2))
    if n < 2:
        return out
    cmds = np.asarray(commands, dtype=np.float64)[: n - 1]
    if travel_poses is not None and len(travel_poses) >= n and np.isfinite(travel_poses[:n]).all():
        p = np.asarray(travel_poses, dtype=np.float64)[:n]
        distance = np.hypot(*np.diff(p[:, :2], axis=0).T)
        sign = np.where(cmds[:, 0] < 0, -1.0, 1.0)
        turn = wrap_angle(np.diff(p[:, 2]))
        out[:, 0], out[:, 1] = sign * distance, turn
        return out
    out[:] = cmds * steps
    return out
