"""A progress gate for subgoal switching, from the robot's own commands (``ControllerConfig.progress_gate``).

Where the view changes little as the robot drives (toward a far wall, along a plain corridor), a subgoal
"matches" while the robot is still 5-15 cm short of it. Each early switch makes the policy steer to a
subgoal further ahead, and the controller's index runs ahead of the robot: on the next curve the robot
steers to a subgoal 30 cm away, cuts the corner and drives the rest of the route beside the path.

Every robot knows what it was told to do: the gate sums the commanded travel since the current subgoal
was set (|v| dt, and |w| dt for turns) and lets the controller switch past subgoal i only when that travel
reaches ``fraction`` of the taught travel into i (from the taught poses i-1 -> i: the distance, the
change of heading, or both on a curve). Travel beyond the gap carries over to the next subgoal and what
fell short of it is owed, so the index follows the commanded travel along the route: with a fraction
under 1 the controller may switch a little early, but the lag cannot grow from subgoal to subgoal. While the policy
still drives toward i the gate holds; a robot that is already at i (it started there, or it overshot) gets
near-zero commands and would wait forever, so after ``patience`` held commands that moved it less than
``IDLE`` of the gap the gate opens.
"""

from __future__ import annotations

import math

import numpy as np

from vtr.runtime.kinematics import wrap_angle

#: Taught moves below these count as none (m, rad): a turn in place has no distance to wait for.
MIN_TRAVEL_M, MIN_TURN_RAD = 0.005, math.radians(0.5)
#: A held command that moved the robot less than this fraction of the gap is idle (the policy is done).
IDLE = 0.05


class ProgressGate:
    """Commanded travel toward the current subgoal, against the taught travel into it."""

    def __init__(self, poses: np.ndarray, n: int, fraction: float, patience: int) -> None:
        """``poses``: the taught (x, y, yaw) of the ``n`` subgoals (NaN where unknown: never gated)."""
        p = np.asarray(poses, dtype=np.float64)[:n]
        if p.shape != (n, 3):
            raise ValueError(f"the progress gate needs (n, 3) taught poses, got {np.shape(poses)}")
        self.fraction, self.patience = float(fraction), int(patience)
        # taught travel INTO subgoal i (subgoal 0: none, the start is not gated)
        self.distance = np.zeros(n)
        self.turn = np.zeros(n)
        self.distance[1:] = np.hypot(*np.diff(p[:, :2], axis=0).T)
        self.turn[1:] = np.abs(wrap_angle(np.diff(p[:, 2])))
        self.index = 0
        self.progress = 0.0  # commanded travel toward ``index``, in units of the taught travel into it
        self.held = 0  # commands the gate held back at this subgoal
        self.idle = 0  # of those, the ones that hardly moved the robot
        self._resync = False

    def _share(self, i: int, distance: float, turn: float) -> float:
        """A move as a fraction of the taught travel into subgoal ``i`` (inf: nothing to wait for)."""
        if not 0 < i < len(self.distance):
            return math.inf
        ratios = []
        if self.distance[i] >= MIN_TRAVEL_M:
            ratios.append(distance / self.distance[i])
        if self.turn[i] >= MIN_TURN_RAD:
            ratios.append(turn / self.turn[i])
        # both parts of a curve: a robot that over-turns has not driven the distance yet
        return min(ratios) if ratios else math.inf  # NaN poses compare False: no ratio, no gate

    def reset(self, index: int) -> None:
        """Subgoal ``index`` was set. After a switch to the next subgoal what the robot travelled beyond the
        previous one counts toward it, and what it fell short is owed: the index follows the commanded
        travel along the route. A jump, a new start, or a switch the patience let through count none."""
        gated = self._share(self.index, 0.0, 0.0) != math.inf  # the previous subgoal had a gap to travel
        carry = gated and index == self.index + 1 and math.isfinite(self.progress) and not self._resync
        self.index, self.progress = index, self.progress - 1.0 if carry else 0.0
        self.held = self.idle = 0
        self._resync = False

    def commanded(self, v: float, w: float, dt: float) -> None:
        """The robot was told to drive (v, w) for dt seconds."""
        share = self._share(self.index, abs(float(v)) * dt, abs(float(w)) * dt)
        self.progress += share
        if self.held and share < IDLE:
            self.idle += 1

    def passes(self, i: int) -> bool:
        """May the controller switch past subgoal ``i`` now? Counts a held command when not."""
        if i != self.index:  # the controller's index is the one source: follow it
            self.reset(i)
        nothing_to_wait_for = self._share(i, 0.0, 0.0) == math.inf
        if nothing_to_wait_for or self.progress >= self.fraction:
            return True
        self.held += 1
        self._resync = self.idle >= self.patience  # the robot is there whatever the commands say
        return self._resync
