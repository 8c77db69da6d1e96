"""What a route's views and taught poses let the follower sense: its camera, the camera-only obstruction
detector and the floor registration (side offset), each None where the route cannot support it."""

from __future__ import annotations

import math

import numpy as np

from vtr.runtime.floor_view import Camera
from vtr.runtime.obstruction import ObstructionDetector
from vtr.runtime.side_offset import SideOffset


def floor_camera(camera: dict[str, object]) -> Camera:
    """The pinhole camera a route's ``camera`` meta describes (its field of view and height where known, the
    shipped camera's where not; the image size comes from the views)."""
    base = Camera()

    def known(key: str, default: float) -> float:
        value = camera.get(key)
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        return float(value) if ok and value > 0 else default  # type: ignore[operator, arg-type]

    return Camera(base.height, base.width, known("fov_deg", base.fov_deg), known("height_m", base.height_m))


def obstruction_detector(
    subgoals: np.ndarray, poses: np.ndarray | None, camera: Camera | None = None
) -> ObstructionDetector | None:
    """The camera-only obstruction detector of a route's views and taught poses (travel poses), or None
    where it cannot work: no poses to warp the floor by, or views too small for a tile to see the floor
    ahead."""
    if poses is None or not np.isfinite(poses).all() or subgoals.dtype != np.uint8:
        return None
    try:
        return ObstructionDetector(subgoals, poses, camera=camera)
    except ValueError:  # no tile of these views sees the path region (or they are no multiple of a tile)
        return None


def side_offset(subgoals: np.ndarray, poses: np.ndarray | None, camera: Camera | None) -> SideOffset | None:
    """The floor registration of a route's views at its taught (travel) poses, or None where it cannot work."""
    if poses is None or not np.isfinite(poses).all() or subgoals.dtype != np.uint8:
        return None
    try:
        return SideOffset(subgoals, poses, camera or Camera())
    except ValueError:  # views too small to see enough floor rows
        return None


__all__ = ["obstruction_detector", "floor_camera", "side_offset"]
