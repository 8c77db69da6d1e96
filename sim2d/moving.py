"""Furniture that moves during a run (the evaluation's moving obstacle): a house and its camera with one
piece translated, everything else shared. Loading a house anew costs over a second (the floor mosaic, the
wall faces, the camera's texture atlas); a translated piece changes only its faces' end points and the
obstacle edges: a median of 5 ms per move on the shared 2-core machine, where loading the house took 1.7 s.
``Simulator.move_furniture`` uses both."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from vtr.sim2d.camera import Camera
from vtr.sim2d.house import House
from vtr.sim2d.rays import Surfaces


def moved_house(house: House, name: str, center: tuple[float, float]) -> House:
    """A copy of ``house`` with the furniture piece ``name`` translated so that its centre is ``center``
    (same shape, height, texture and orientation); walls, floor, textures and start poses are shared."""
    index = next((i for i, f in enumerate(house.furniture) if f.name == name), None)
    if index is None:
        raise ValueError(f"{house.source}: no furniture named {name!r}")
    piece = house.furniture[index]
    shift = np.asarray(center, dtype=np.float64) - np.asarray(piece.center, dtype=np.float64)
    new = copy.copy(house)
    new.furniture = list(house.furniture)
    new.furniture[index] = dataclasses.replace(
        piece, vertices=piece.vertices + shift, center=(float(center[0]), float(center[1]))
    )
    # the faces: walls first, then each piece's polygon in furniture order (House._build_segments)
    first = int(house.segments.is_wall.sum()) + sum(len(f.vertices) for f in house.furniture[:index])
    rows = slice(first, first + len(piece.vertices))
    a, b = house.segments.a.copy(), house.segments.b.copy()
    a[rows] += shift
    b[rows] += shift
    new.segments = dataclasses.replace(house.segments, a=a, b=b)
    new._build_obstacles()
    return new


def moved_camera(camera: Camera, house: House) -> Camera:
    """``camera`` rendering ``house``, a :func:`moved_house` of the one it was built for: the faces' end
    points are new, their textures, shading tables and the atlas are shared."""
    new = copy.copy(camera)
    seg = house.segments
    order = np.argsort(~seg.is_wall, kind="stable")  # as Camera.__init__: walls first
    new.house = house
    new.seg_a, new.seg_b = seg.a[order], seg.b[order]
    new.seg_e = new.seg_b - new.seg_a
    new.seg_len = np.hypot(new.seg_e[:, 0], new.seg_e[:, 1])
    new._surfaces = Surfaces(new.seg_a, new.seg_b)
    new._ends_t = np.concatenate([new.seg_a, new.seg_b]).T.copy()
    return new


__all__ = ["moved_camera", "moved_house"]
