"""Repeat-time conditions: what changed between teach and repeat, applied to the repeat only.

Two kinds, each deterministic and named so a run is reproducible from the command line:

- **lighting** (``LIGHTING``): a function of the camera image, applied by :class:`LitRobot` to every frame
  the runtime receives (the taught route is untouched): global gain, a colour cast, one side darker.
- **scene** (``SCENES``): a changed house, written as a modified copy of the house JSON that the repeat's
  simulator loads: one wall per room re-textured, every piece of furniture moved, part of the floor
  re-coloured; and, relative to the taught path (``PATH_SCENES``), a box placed beside it, or one placed
  on it half-way along (the way blocked by design: the robot must stop before it). The robot's physics
  sees moved furniture and the boxes.
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


class ClearingRobot:
    """Wraps a LocalRobot and takes the path scene's box away (the simulator's house swapped for
    ``cleared_house``, the robot where it stands) once the robot has stood still for ``after_s`` seconds:
    the box removed while the robot waits. Standing time is counted from zero-velocity steps, and, as the
    lockstep simulator's clock does not move between steps, each view polled while standing counts one
    control period ``dt``."""

    def __init__(self, robot: Any, cleared_house: str, after_s: float, dt: float) -> None:
        self.robot, self.cleared_house, self.after_s, self.dt = robot, cleared_house, after_s, dt
        self.cleared_at: float | None = None  # simulated time of the removal
        self._stood = 0.0

    @property
    def last(self) -> Observation | None:
        return self.robot.last

    def _stand(self, seconds: float) -> None:
        self._stood += seconds
        if self.cleared_at is None and self._stood >= self.after_s - 1e-9:
            self.robot.sim.set_house(self.cleared_house)
            self.cleared_at = float(self.robot.sim.time)

    def reset(self, pose: tuple[float, float, float] | None = None, seed: int | None = None) -> Observation:
        self._stood = 0.0
        return self.robot.reset(pose=pose, seed=seed)

    def observe(self) -> Observation:
        self._stand(self.dt)
        return self.robot.observe()

    def step(self, v: float, w: float, duration: float) -> Observation:
        if abs(v) < 1e-6 and abs(w) < 1e-6:
            self._stand(duration)
        else:
            self._stood = 0.0
        return self.robot.step(v, w, duration)

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
            box = {
                "name": "box",
                "shape": "box",
                "center": [cx, cy],
                "size": [BOX_SIDE] * 2,
                "height": 0.4,
                "texture": "metal_blue",
                "angle_deg": math.degrees(yaw),
            }
            try:
                House({**house, "furniture": [*house["furniture"], box]}, "obstacle_beside_path")
            except ValueError:
                continue
            house["furniture"].append(box)
            return
    raise ValueError("no room for a box beside this path")


#: The box put on the taught path (box_on_path, box_removed): side (m); its name in the house's furniture.
PATH_BOX_SIDE, BOX_NAME = 0.25, "box"


def _along(path: np.ndarray, fraction: float) -> tuple[float, float, float]:
    """The (x, y, yaw) ``fraction`` of the way along the taught path's length (yaw of the gap it lies on)."""
    xy = path[:, :2]
    gaps = np.hypot(*np.diff(xy, axis=0).T)
    arc = np.concatenate([[0.0], np.cumsum(gaps)])
    s = fraction * arc[-1]
    k = int(np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(xy) - 2))
    t = (s - arc[k]) / gaps[k] if gaps[k] > 0 else 0.0
    x, y = xy[k] + t * (xy[k + 1] - xy[k])
    yaw = math.atan2(*(xy[k + 1] - xy[k])[::-1]) if gaps[k] > 0 else float(path[k, 2])
    return float(x), float(y), yaw


def _box_on_path(house: dict[str, Any], path: np.ndarray | None) -> None:
    """A 25 cm box centred on the taught path half-way along its length, square to it: the way is blocked
    by design (the robot must stop before it). Start poses of the house it would cover are dropped."""
    from vtr.sim2d.house import START_CLEARANCE, House

    if path is None or len(path) < 2 or not np.hypot(*np.diff(path[:, :2], axis=0).T).sum() > 0:
        raise ValueError("the box_on_path scene needs a taught path that moves")
    cx, cy, yaw = _along(path, 0.5)
    box = {
        "name": BOX_NAME,
        "shape": "box",
        "center": [cx, cy],
        "size": [PATH_BOX_SIDE] * 2,
        "height": 0.4,
        "texture": "metal_blue",
        "angle_deg": math.degrees(yaw),
    }
    reach = START_CLEARANCE + PATH_BOX_SIDE / math.sqrt(2)  # a start this close may touch the box
    starts = [p for p in house["start_poses"] if math.hypot(p["x"] - cx, p["y"] - cy) > reach]
    changed = {**house, "start_poses": starts, "furniture": [*house["furniture"], box]}
    House(changed, "box_on_path")  # raises where the box does not fit (it always should on a taught path)
    house.update(changed)


def box_of(house: dict[str, Any]) -> dict[str, Any] | None:
    """The box a path scene added to ``house`` (None without one)."""
    return next((f for f in house["furniture"] if f.get("name") == BOX_NAME), None)


def box_distance(box: dict[str, Any], x: float, y: float) -> float:
    """Distance (m) from (x, y) to the nearest face of a "box" furniture item (0 inside it)."""
    a = math.radians(float(box.get("angle_deg", 0.0)))
    dx, dy = x - box["center"][0], y - box["center"][1]
    u, v = math.cos(a) * dx + math.sin(a) * dy, -math.sin(a) * dx + math.cos(a) * dy
    hx, hy = box["size"][0] / 2, box["size"][1] / 2
    return math.hypot(max(abs(u) - hx, 0.0), max(abs(v) - hy, 0.0))


def without_box(house: dict[str, Any]) -> dict[str, Any]:
    """A copy of ``house`` with the path scene's box taken away (box_removed: the way clears)."""
    return {**house, "furniture": [f for f in house["furniture"] if f.get("name") != BOX_NAME]}


def path_box(house: str) -> dict[str, Any] | None:
    """The path scene's box in a house JSON file (None for a map name or a house without one)."""
    path = Path(house)
    if path.suffix != ".json" or not path.is_file():
        return None
    return box_of(json.loads(path.read_text(encoding="utf-8")))


def write_cleared_house(house: str) -> Path:
    """Beside a house JSON file with the path scene's box, the same house without it; returns its path."""
    from vtr.runtime.atomic import write_text_atomic

    path = Path(house)
    out = path.with_name(f"{path.stem}_cleared.json")
    write_text_atomic(out, json.dumps(without_box(json.loads(path.read_text(encoding="utf-8")))))
    return out


SCENES: dict[str, Callable[[dict[str, Any]], None]] = {
    "wall_retextured": _retexture_walls,
    "furniture_moved": _move_furniture,
    "floor_recoloured": _recolour_floor,
}
#: Scene changes placed relative to the taught path (they take it as a second argument).
PATH_SCENES: dict[str, Callable[[dict[str, Any], np.ndarray | None], None]] = {
    "obstacle_beside_path": _obstacle_beside_path,
    "box_on_path": _box_on_path,
}
#: Scenes that block the taught path by design: no PathBlocked refusal (the robot must stop before them).
BLOCKING_SCENES = ("box_on_path",)


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
