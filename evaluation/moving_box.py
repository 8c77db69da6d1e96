"""A box that crosses the taught path ahead of the robot and goes on (the condition suite's
``moving_obstacle``): someone carrying a crate across the room. The scene puts the path scenes' box beside
the path half-way along (``box_crossing_path``); :class:`CrossingRobot` starts it moving once the robot is
``TRIGGER_M`` from the crossing point, at ``SPEED`` m/s straight across to the other side, through
``Simulator.move_furniture``. The robot should finish the route without touching it: stop for it or pass
behind it."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vtr.evaluation.path_boxes import BOX_NAME, PATH_BOX_SIDE, along_path, box_distance, box_item, densified
from vtr.runtime.robot import Observation

#: The box starts moving when the robot's centre is this far (m) from the crossing point, and moves at this
#: speed (m/s): with the robot at 0.2 m/s it crosses the path about 1 m ahead of the robot.
TRIGGER_M, SPEED = 1.5, 0.4
#: How far to the side (m, the box's centre from the path) it starts and ends, the farthest that fits on
#: each side (0.45: its face 0.155 m clear of the robot's body on the path).
SWEEP_SIDES = (0.8, 0.65, 0.5, 0.45)
#: Where along the path (share of its length) it may cross, tried in this order.
CROSSINGS = (0.5, 0.4, 0.6, 0.3, 0.7)


def _sweep_free(house: Any, start: np.ndarray, end: np.ndarray) -> bool:
    """The box's centre can travel from start to end without touching walls or furniture."""
    n = max(2, int(np.hypot(*(end - start)) / 0.05) + 1)
    points = start + np.linspace(0.0, 1.0, n)[:, None] * (end - start)
    return bool((house.clearances(points) >= PATH_BOX_SIDE / math.sqrt(2) + 0.02).all())


def _farthest(
    house: Any, dense: np.ndarray, centre: np.ndarray, normal: np.ndarray, yaw: float
) -> np.ndarray | None:
    """The place along ``normal`` from ``centre`` on the path farthest out (of SWEEP_SIDES) that the box
    can reach from the path, no part of the path (``dense``) nearer to it than to ``centre``."""
    for side_m in SWEEP_SIDES:
        point = centre + side_m * normal
        nearest = min(box_distance(box_item(*point, yaw), px, py) for px, py in dense)
        if nearest >= side_m - PATH_BOX_SIDE / 2 - 1e-3 and _sweep_free(house, centre, point):
            return point
    return None


def box_crossing_path(house: dict[str, Any], path: np.ndarray | None) -> None:
    """The box beside the path where it will cross: square to the path, half-way along (else CROSSINGS), as
    far to one side as SWEEP_SIDES allows, with a free sweep straight across the path to as far on the
    other side as they allow (the item's ``sweep_to``), neither end nearer to any part of the path than its
    side offset. Generated routes keep 0.3 m from furniture, so a symmetric sweep often does not fit."""
    from vtr.sim2d.house import House

    if path is None or len(path) < 2 or not np.hypot(*np.diff(path[:, :2], axis=0).T).sum() > 0:
        raise ValueError("the moving_obstacle scene needs a taught path that moves")
    dense, before = densified(path), House(house, "unchanged")
    for fraction in CROSSINGS:
        x, y, yaw = along_path(path, fraction)
        centre, normal = np.array([x, y]), np.array([-math.sin(yaw), math.cos(yaw)])

        left, right = (_farthest(before, dense, centre, side * normal, yaw) for side in (1.0, -1.0))
        if left is None or right is None:
            continue
        for start, end in ((left, right), (right, left)):
            # where it crosses and where it goes (the house ignores the keys)
            box = {**box_item(*start, yaw), "crossing": [x, y], "sweep_to": [float(end[0]), float(end[1])]}
            changed = {**house, "furniture": [*house["furniture"], box]}
            try:
                House(changed, "moving_obstacle")
            except ValueError:
                continue
            house.update(changed)
            return
    raise ValueError("no free floor for a box to cross this path")


class CrossingRobot:
    """Wraps a LocalRobot whose house has the crossing ``box`` (:func:`box_crossing_path`'s item): moves it
    straight across the path, through its ``crossing`` point to ``sweep_to`` on the other side, once the robot
    comes within ``TRIGGER_M`` of that point, before each step by the distance it covers in that step; where
    it would overlap the robot it waits. ``closest``: the least distance (m) from the robot's centre to the
    box's nearest face so far (contact at the robot's radius)."""

    def __init__(self, robot: Any, box: dict[str, Any]) -> None:
        self.robot = robot
        self.start = np.asarray(box["center"], dtype=np.float64)
        self.end = np.asarray(box["sweep_to"], dtype=np.float64)
        self.crossing = np.asarray(box["crossing"], dtype=np.float64)
        self.length = float(np.hypot(*(self.end - self.start)))
        self.angle_deg = float(box.get("angle_deg", 0.0))
        self.travelled = 0.0
        self.started_at: float | None = None  # simulated time the box began to move
        self.closest = math.inf

    @property
    def last(self) -> Observation | None:
        return self.robot.last

    @property
    def box(self) -> dict[str, Any]:
        """The box where it is now, as a house's furniture item (for box_distance)."""
        t = min(self.travelled / self.length, 1.0) if self.length > 0 else 1.0
        center = self.start + t * (self.end - self.start)
        return {"center": center.tolist(), "size": [PATH_BOX_SIDE] * 2, "angle_deg": self.angle_deg}

    def _seen(self, obs: Observation) -> Observation:
        if obs.pose is not None:
            self.closest = min(self.closest, box_distance(self.box, *obs.pose[:2]))
        return obs

    def _move(self, duration: float) -> None:
        sim = self.robot.sim
        pose = sim.pose
        if self.started_at is None:
            if math.hypot(pose.x - self.crossing[0], pose.y - self.crossing[1]) > TRIGGER_M:
                return
            self.started_at = float(sim.time)
        if self.travelled >= self.length:
            return
        ahead = min(self.travelled + SPEED * duration, self.length)
        center = self.start + (ahead / self.length) * (self.end - self.start)
        try:
            sim.move_furniture(BOX_NAME, (float(center[0]), float(center[1])))
        except ValueError:  # it would run into the robot: it waits
            return
        self.travelled = ahead

    def reset(self, pose: tuple[float, float, float] | None = None, seed: int | None = None) -> Observation:
        return self._seen(self.robot.reset(pose=pose, seed=seed))

    def observe(self) -> Observation:
        return self._seen(self.robot.observe())

    def step(self, v: float, w: float, duration: float) -> Observation:
        self._move(duration)
        return self._seen(self.robot.step(v, w, duration))

    def stop(self) -> None:
        self.robot.stop()


__all__ = ["SPEED", "TRIGGER_M", "CrossingRobot", "box_crossing_path"]
