"""The one teach recorder: observations in, subgoals out, by :class:`TeachConfig`'s spacing rule.

A scripted teach (``runtime.teach``), a teach by keyboard (``--drive``) and a teach that watches someone else
drive (``--follow``, ``runtime.teach_drive``) all feed their control steps through :class:`TeachRecorder`, so a
route's subgoals are spaced alike whoever drove it. A control step counts towards the ``"steps"`` rule only
while the robot moves: a driver who stops to think adds no subgoals of the same view (a scripted route always
moves, so its spacing is unchanged).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vtr.runtime.robot import Observation
from vtr.runtime.route import Route
from vtr.runtime.safety import limit_twist
from vtr.runtime.scan import Scan


class TeachRecorder:
    """Record subgoals while a robot is driven; ``cfg`` is a ``runtime.teach.TeachConfig``."""

    def __init__(self, cfg: Any, first: Observation) -> None:
        self.cfg = cfg
        self.images: list[np.ndarray] = []
        self.poses: list[tuple[float, float, float]] = []
        self.commands: list[list[float]] = []
        self.scans: list[Scan | None] = []  # the range scan at each subgoal, when the robot has one
        self.pending = False  # the last subgoal still waits for the command that follows it
        self.since = 0  # moving control steps since the last subgoal
        self.last = first
        self._add(first)

    def __len__(self) -> int:
        return len(self.images)

    def _add(self, obs: Observation) -> None:
        self.images.append(np.array(obs.image, dtype=np.uint8, copy=True))
        self.poses.append(obs.pose if obs.pose is not None else (math.nan, math.nan, math.nan))
        self.commands.append([0.0, 0.0])
        self.scans.append(obs.scan)
        self.pending = True

    def step(self, v: float, w: float, obs: Observation, moving: bool = True) -> bool:
        """One control step that applied (v, w) and then saw ``obs``; True when ``obs`` became a subgoal.
        ``moving`` False (the robot stood still) leaves the spacing untouched."""
        self.last = obs
        if not moving:
            return False
        if self.pending:
            self.commands[-1] = [float(v), float(w)]
            self.pending = False
        self.since += 1
        if self.cfg.subgoal_due(self.since, obs, self.images[-1], self.poses[-1]):
            self._add(obs)
            self.since = 0
            return True
        return False

    def finish(self, name: str, info: dict[str, Any]) -> Route:
        """The route: the last view becomes the final subgoal when the robot moved since the last one."""
        if self.since > 0:
            self._add(self.last)
            self.since = 0
        commands = np.array(self.commands, dtype=np.float64)
        height, width = self.images[0].shape[:2]
        camera = info.get("camera")
        return Route(
            images=np.stack(self.images),
            poses=np.array(self.poses, dtype=np.float64),
            commands=commands,
            name=name,
            camera=camera if isinstance(camera, dict) else {"height": height, "width": width},
            spacing=self.cfg.rule(),
            map=info.get("map") if isinstance(info.get("map"), str) else None,
            dt=self.cfg.dt,
            clearance=taught_clearance(self.scans, commands),
        )


def taught_clearance(scans: list[Scan | None], commands: np.ndarray) -> np.ndarray | None:
    """(L,) free distance (m) the teach's range scan showed at each subgoal along the arc it drove (the
    command after it, else the one before; straight ahead in a turn in place; inf: nothing in range), or
    None when the robot sent no scans.
    The repeat's stop zone never reaches further than what the teach itself drove up to (runtime.safety)."""
    if all(s is None for s in scans):
        return None
    out = np.full(len(scans), np.nan)
    for i, scan in enumerate(scans):
        if scan is None:
            continue
        v, w = commands[i] if commands[i, 0] != 0 or i == 0 else commands[i - 1]
        seen = limit_twist(v, w, scan).distance if v else limit_twist(1.0, 0.0, scan).distance  # on its arc
        out[i] = math.inf if seen is None else seen
    return out
