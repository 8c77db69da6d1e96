"""A floor world for the camera-only obstruction tests: what a level pinhole camera 0.3 m above a floor of
coloured squares sees, with a box drawn in front of it (the model runtime.floor_view assumes, drawn apart)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vtr.runtime.floor_view import Camera

CAM = Camera()


def floor_view(
    x: float,
    y: float = 0.0,
    yaw: float = 0.0,
    seed: int = 0,
    cam: Camera = CAM,
    tilt: float = 0.0,
    stripes: bool = False,
    size: float = 0.2,
) -> np.ndarray:
    """What ``cam`` sees from (x, y, yaw) over a floor of squares ``size`` m on a side (20 cm) in random colours
    (grey above the horizon; sim2d's mosaic is coarser still), laid ``tilt`` rad to the x axis: laid along it
    (0), a floor row seen along x shows the same colours over the length of a square, which tells no distance
    along x (as planks laid along the path do); sim2d's mosaic has edges at every angle. ``stripes``: planks
    ``size`` m wide instead, each of one colour along its length (which runs ``tilt`` rad from the y axis), so
    that a step along x looks as a step along y does."""
    colours = np.random.default_rng(seed).integers(30, 220, (64, 64, 3))
    f = cam.focal_px
    rows, cols = np.mgrid[0 : cam.height, 0 : cam.width] + 0.5
    down, right = (rows - cam.height / 2) / f, (cols - cam.width / 2) / f
    ahead = cam.height_m / np.where(down > 0, down, np.nan)
    with np.errstate(invalid="ignore"):
        fx = x + math.cos(yaw) * ahead + math.sin(yaw) * right * ahead
        fy = y + math.sin(yaw) * ahead - math.cos(yaw) * right * ahead
        fx, fy = math.cos(tilt) * fx + math.sin(tilt) * fy, math.cos(tilt) * fy - math.sin(tilt) * fx
        i, j = np.floor(fx / size).astype(int) % 64, np.floor(fy / size).astype(int) % 64
        if stripes:  # one colour along each plank's length
            j = np.zeros_like(j)
    out = colours[np.where(down > 0, i, 0), np.where(down > 0, j, 0)]
    out[down <= 0] = 128
    return out.astype(np.uint8)


def straight_route(
    n: int = 24, gap: float = 0.1, cam: Camera = CAM, **floor: Any
) -> tuple[np.ndarray, np.ndarray]:
    """The views (seen by ``cam``) and poses of a straight route along x, a subgoal every ``gap`` m, over the
    floor :func:`floor_view` lays with ``floor`` (``tilt``, ``stripes``, ``size``)."""
    poses = np.array([[gap * k, 0.0, 0.0] for k in range(n)])
    return np.stack([floor_view(x, cam=cam, **floor) for x, _, _ in poses]), poses


def with_blob(image: np.ndarray, rows: slice, cols: slice) -> np.ndarray:
    """``image`` with a face of blue planks over ``rows`` x ``cols`` (a plain face on a plain floor tile
    matches it: nothing in a plain patch tells them apart)."""
    out = image.copy()
    planks = np.where((np.arange(out.shape[1]) // 4) % 2, 200, 120)[cols]
    out[rows, cols] = np.stack([planks // 4, planks // 2, planks], axis=-1)[None]
    return out


def box_at(image: np.ndarray, distance: float, side: float = 0.25) -> np.ndarray:
    """``image`` with a box ``side`` wide and taller than the camera standing ``distance`` m ahead."""
    f, h = CAM.focal_px, CAM.height_m
    base, half = 64 + int(f * h / distance), max(1, int(f * side / 2 / distance))
    return with_blob(image, slice(40, min(base, 128)), slice(64 - half, 64 + half))


def corridor_view(
    x: float, y: float = 0.0, yaw: float = 0.0, seed: int = 0, half_m: float = 0.5
) -> np.ndarray:
    """:func:`floor_view` between two walls ``half_m`` to each side of the x axis, of 5 x 5 cm blocks of random
    colours that stay when the floor is laid again (``seed``)."""
    out = floor_view(x, y, yaw, seed)
    colours = np.random.default_rng(99).integers(30, 220, (256, 64, 3))
    f = CAM.focal_px
    rows, cols = np.mgrid[0 : CAM.height, 0 : CAM.width] + 0.5
    down, right = (rows - CAM.height / 2) / f, (cols - CAM.width / 2) / f
    left = math.sin(yaw) - math.cos(yaw) * right  # metres to the left per metre ahead
    floor_at = CAM.height_m / np.where(down > 0, down, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        wall_at = np.where(left > 0, half_m - y, -half_m - y) / left
        wall = (wall_at > 0) & ~(floor_at < wall_at)
        along = x + (math.cos(yaw) + math.sin(yaw) * right) * wall_at
        up = CAM.height_m - down * wall_at
        i = np.floor(np.where(wall, along, 0) / 0.05).astype(int) % 256
        j = np.clip(np.floor(np.where(wall, up, 0) / 0.05).astype(int), 0, 63)
    out[wall] = colours[i, j][wall]
    return out
