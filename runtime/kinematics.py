"""The unicycle the protocol's (v, w) commands drive: one source for the arc a held command traces."""

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
