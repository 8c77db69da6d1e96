"""Repeat-time conditions: what changed between teach and repeat, applied to the repeat only.

Two kinds, each deterministic and named so a run is reproducible from the command line:

- **lighting** (``LIGHTING``): a function of the camera image, applied by :class:`LitRobot` to every frame
  the runtime receives (the taught route is untouched): global gain, a colour cast, one side darker.
- **scene** (``SCENES``): a changed house, written as a modified copy of the house JSON that the repeat's
  simulator loads: one wall per room re-textured, every piece of furniture moved, part of the floor
  re-coloured; and, relative to the taught path (``PATH_SCENES``), a box placed beside it
  (``obstacle_beside_path``, ``box_beside_path``), one placed on it half-way along (the way blocked by
  design: the robot must stop before it), or one that crosses it ahead of the robot (``moving_obstacle``,
  evaluation.moving_box). The robot's physics sees moved furniture and the boxes.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from vtr.evaluation.moving_box import box_crossing_path
from vtr.evaluation.path_boxes import box_after_turn, box_beside_path, box_item, box_on_path
from vtr.runtime.robot import Observation
from vtr.sim2d.config import SimConfig

ImageFn = Callable[[np.ndarray], np.ndarray]


def _gain(image: np.ndarray, gain: np.ndarray | float) -> np.ndarray:
    out = image.astype(np.float32) * gain
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def brightness(factor: float) -> ImageFn:
    """Every pixel times ``factor`` (saturating at 255), as a camera's exposure or a dimmer would."""
    return lambda image: _gain(image, np.float32(factor))


def colour_cast(gains: tuple[float, float, float] = (1.2, 1.0, 0.75)) -> ImageFn:
    """Per-channel gains: warm evening light by default."""
    g = np.asarray(gains, dtype=np.float32)
    return lambda image: _gain(image, g)


def side_darker(low: float = 0.45, side: str = "left") -> ImageFn:
    """A horizontal ramp of gain from ``low`` at one edge to 1 at the other: one lamp off."""

    def apply(image: np.ndarray) -> np.ndarray:
        ramp = np.linspace(low, 1.0, image.shape[1], dtype=np.float32)
        if side == "right":
            ramp = ramp[::-1]
        return _gain(image, ramp[None, :, None])

    return apply


LIGHTING: dict[str, ImageFn] = {
    "bright_0.6": brightness(0.6),
    "bright_0.7": brightness(0.7),
    "bright_1.3": brightness(1.3),
    "bright_1.5": brightness(1.5),
    "colour_cast": colour_cast(),
    "left_darker": side_darker(0.45, "left"),
}


class LitRobot:
    """Wraps a Robot and changes the light of every frame it returns (the repeat-time lighting)."""

    def __init__(self, robot: Any, light: ImageFn) -> None:
        self.robot, self.light = robot, light

    @property
    def last(self) -> Observation | None:
        """The wrapped robot's last observation, unlit (the evaluation scores with its true pose)."""
        return self.robot.last

    def _lit(self, obs: Observation) -> Observation:
        return replace(obs, image=self.light(obs.image))  # pose, contact and range scan pass through

    def reset(self, pose: tuple[float, float, float] | None = None, seed: int | None = None) -> Observation:
        return self._lit(self.robot.reset(pose=pose, seed=seed))

    def observe(self) -> Observation:
        return self._lit(self.robot.observe())

    def step(self, v: float, w: float, duration: float) -> Observation:
        return self._lit(self.robot.step(v, w, duration))

    def stop(self) -> None:
        self.robot.stop()


# ------------------------------------------------------------------------------------------ scene changes


def _retexture_walls(house: dict[str, Any]) -> None:
    """Each room's north wall gets a new pattern and colours (a repainted wall or a new poster)."""
    for room in house["rooms"]:
        name = room["walls"]["n"]
        house["textures"][name] = {
            "kind": "dots",
            "colors": [[60, 160, 150], [245, 235, 210]],
            "size": [0.35, 0.35],
            "count": 3,
        }


def _move_furniture(house: dict[str, Any], shift: tuple[float, float] = (0.3, 0.0)) -> None:
    """Every piece of furniture moved 30 cm along +x (a box shifted, a table pushed)."""
    for item in house["furniture"]:
        if "center" in item:
            item["center"] = [item["center"][0] + shift[0], item["center"][1] + shift[1]]
        if "points" in item:
            item["points"] = [[p[0] + shift[0], p[1] + shift[1]] for p in item["points"]]


def _recolour_floor(house: dict[str, Any]) -> None:
    """The floor mosaic drawn from another seed and darker grout (a new rug, re-laid tiles)."""
    house["floor"]["seed"] = int(house["floor"].get("seed", 0)) + 101
    house["floor"]["grout"] = [110, 80, 50]


#: Box placed beside the path: side (m), and the gap between its edge and the robot's body on the path.
BOX_SIDE, BOX_GAP = 0.3, 0.12
ROBOT_RADIUS = SimConfig().robot_radius


class PathBlocked(ValueError):
    """The changed house leaves no room for the robot on the taught path: no repeat can pass untouched."""


def path_clearance(house: dict[str, Any], path: np.ndarray, per_gap: int = 4) -> tuple[float, int]:
    """The least distance (m) from the taught path (x, y, yaw poses, with ``per_gap`` points between
    consecutive ones) to a wall or piece of furniture of ``house``, and the pose index where it is."""
    from vtr.sim2d.house import House

    xy = np.asarray(path, dtype=np.float64)[:, :2]
    t = np.arange(per_gap) / per_gap
    dense = (
        (xy[:-1, None] * (1 - t)[:, None] + xy[1:, None] * t[:, None]).reshape(-1, 2) if len(xy) > 1 else xy
    )
    dense = np.vstack([dense, xy[-1:]])
    c = House(house, "changed").clearances(dense)
    k = int(np.argmin(c))
    return float(c[k]), min(k // per_gap, len(xy) - 1)


def _obstacle_beside_path(house: dict[str, Any], path: np.ndarray | None) -> None:
    """A 30 cm box on the floor beside the taught path, 12 cm clear of the robot's body on it: something
    new in view that the robot must not touch. Placed beside the middle of the path, left then right, else
    beside a point further from it (1/3, 2/3, 1/4, ...), on free floor where the house stays valid."""
    from vtr.sim2d.house import House

    if path is None or len(path) < 2:
        raise ValueError("the obstacle_beside_path scene needs the taught path")
    offset = ROBOT_RADIUS + BOX_GAP + BOX_SIDE / 2
    before = House(house, "unchanged")
    for k in (len(path) * f // 12 for f in (6, 4, 8, 3, 9, 2, 10)):
        x, y, yaw = (float(v) for v in path[k])
        for side in (1.0, -1.0):
            cx, cy = x - side * math.sin(yaw) * offset, y + side * math.cos(yaw) * offset
            if (
                np.hypot(path[:, 0] - cx, path[:, 1] - cy).min() < offset - 1e-6
                or before.clearance(cx, cy) < BOX_SIDE
            ):
                continue  # on the path, or in (or against) furniture already there
            box = box_item(cx, cy, yaw, BOX_SIDE, "box")
            try:
                House({**house, "furniture": [*house["furniture"], box]}, "obstacle_beside_path")
            except ValueError:
                continue
            house["furniture"].append(box)
            return
    raise ValueError("no room for a box beside this path")


SCENES: dict[str, Callable[[dict[str, Any]], None]] = {
    "wall_retextured": _retexture_walls,
    "furniture_moved": _move_furniture,
    "floor_recoloured": _recolour_floor,
}
#: Scene changes placed relative to the taught path (they take it as a second argument).
PATH_SCENES: dict[str, Callable[[dict[str, Any], np.ndarray | None], None]] = {
    "obstacle_beside_path": _obstacle_beside_path,
    "box_on_path": box_on_path,
    "box_after_turn": box_after_turn,
    "box_beside_path": box_beside_path,
    "moving_obstacle": box_crossing_path,
}
#: Scenes that block the taught path by design: no PathBlocked refusal (the robot must stop before them).
BLOCKING_SCENES = ("box_on_path", "box_after_turn")
#: Scenes whose box moves during the run (evaluation.moving_box.CrossingRobot moves it).
MOVING_SCENES = ("moving_obstacle",)


def write_scene_house(
    scene: str,
    out_dir: Path,
    base: str = "house",
    path: np.ndarray | None = None,
    allow_blocked: bool = False,
) -> Path:
    """A copy of the house JSON with ``scene`` applied, written into ``out_dir``; returns its path.

    ``path``: the taught (x, y, yaw) poses, for the scenes in PATH_SCENES and for the check that the change
    leaves the path passable (:class:`PathBlocked` otherwise, unless ``allow_blocked`` or the scene blocks it
    by design, BLOCKING_SCENES)."""
    from vtr.runtime.atomic import write_text_atomic
    from vtr.sim2d.house import resolve_house_path

    if scene not in SCENES and scene not in PATH_SCENES:
        raise ValueError(f"unknown scene change {scene!r}; known: {', '.join([*SCENES, *PATH_SCENES])}")
    data = copy.deepcopy(json.loads(resolve_house_path(base).read_text(encoding="utf-8")))
    if scene in SCENES:
        SCENES[scene](data)
    else:
        PATH_SCENES[scene](data, None if path is None else np.asarray(path, dtype=np.float64))
    if path is not None and not allow_blocked and scene not in BLOCKING_SCENES and len(path):
        # moving every piece of furniture 30 cm can put one on the taught path: a repeat cannot pass it
        # untouched, so such a run would score the scene, not the robot
        gap, k = path_clearance(data, np.asarray(path, dtype=np.float64))
        if gap < ROBOT_RADIUS:
            raise PathBlocked(
                f"the {scene} house blocks the taught path: {gap:.3f} m of clearance near subgoal "
                f"{k}, under the robot's radius {ROBOT_RADIUS} m"
            )
    path = Path(out_dir) / f"house_{scene}.json"
    write_text_atomic(path, json.dumps(data))
    return path
