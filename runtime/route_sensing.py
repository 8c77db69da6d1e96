"""What a route's views and taught poses let the follower sense: its camera, the camera-only obstruction
detector and the floor registration (side offset), each None where the route cannot support it."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from vtr.runtime.floor_view import Camera
from vtr.runtime.frame import Frame
from vtr.runtime.hello import current_camera_names
from vtr.runtime.obstruction import ObstructionDetector
from vtr.runtime.side_offset import SideEstimate, SideOffset

#: A view's floor registration, asked when needed and made once (:func:`floor_side_of`).
FloorSide = Callable[[], "SideEstimate | None"]


def floor_camera(camera: dict[str, object]) -> Camera:
    """The pinhole camera a route's ``camera`` meta describes (its field of view and height where known, the
    shipped camera's where not; the image size comes from the views). Older names are read as hello reads them
    (``hello.current_camera_names``): routes taught on the simulator recorded ``camera_height``."""
    base = Camera()
    camera = current_camera_names(camera)

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


def floor_side_of(registration: SideOffset | None, image: Frame, position: float) -> FloorSide | None:
    """Where the floor of ``image`` puts the robot beside the taught pose at ``position``, computed when first
    asked and then kept for the view: the obstruction detector and the side turn both ask it (None: no floor
    registration)."""
    if registration is None:
        return None
    found: list[SideEstimate | None] = []

    def at() -> SideEstimate | None:
        if not found:
            found.append(registration.estimate(image, position))
        return found[0]

    return at


__all__ = ["FloorSide", "floor_camera", "floor_side_of", "obstruction_detector", "side_offset"]
