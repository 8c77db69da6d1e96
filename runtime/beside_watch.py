"""How far the robot's own commands have taken it beside the taught path since a view or the floor last placed it:
dead reckoning between evidence, so that the follower never drives on blind, away from the path.

The route localiser places the robot along the route, and the commanded motion carries that estimate along the
route whichever way the robot drives. Where no view matches a subgoal under its threshold and the floor tells no
side offset, a robot turned off the taught heading drives away from the path while the estimate still moves
along it: held-out set 46, two starts 10 cm / 10 deg off the route turned 20-60 deg past the path while closing
the offset, matched nothing from then on, and drove 0.7-1.4 m until they touched furniture. The robot's own
commands say where it went: the heading they turned since the evidence, against the heading the teach had at the
estimate, and the distance driven at it. A view matching a subgoal puts the robot on the taught heading (a view
turned a few degrees off no longer matches); the floor's side estimate (``runtime.side_offset``) puts it ``psi``
off it. The offset is counted from there: the offset the floor reads is the side turn's to close
(``runtime.side_turn``), and one reading can be centimetres off or more, where the pursuit takes the median of
several. Past ``BESIDE_M`` the follower ends the run LOST with this evidence (``Follower._stalled``).
"""

from __future__ import annotations

import math

import numpy as np

from vtr.runtime.side_offset import SideEstimate

#: The offset (m) the commands may take the robot beside the taught path without a view or the floor placing it
#: again. On the development check (1,376 runs: routes gen_100-179 under 8 conditions, houses random:900-999, and
#: 900-959 at two more cameras) no run came past 0.079 m, none that completed past 0.056 m (a re-coloured floor); the two blind
#: drives of held-out set 46 reached 0.42 and 0.43 m when they touched furniture. Not a clearance: the camera
#: stop and the range scan's zones keep the robot off what is in the way.
BESIDE_M = 0.2


class BesideWatch:
    """Dead-reckons the robot's offset from the taught path between views that place it (module docstring)."""

    def __init__(self, motion: np.ndarray | None) -> None:
        """``motion``: (L-1, 2) the taught motion of each gap (``kinematics.taught_motion``: metres forward,
        radians counter-clockwise); None where the route has no taught path (``Route.travel_poses``): no watch."""
        turns = None if motion is None else np.asarray(motion, dtype=np.float64).reshape(-1, 2)[:, 1]
        #: the taught heading at each subgoal (rad), from the first subgoal's
        self.taught = None if turns is None else np.concatenate([[0.0], np.cumsum(turns)])
        self.reset()

    def reset(self) -> None:
        """Nothing known (a new start, a search of the whole route): the next view sets the heading."""
        #: the heading the commands turned to (rad, in the taught heading's frame); None before a view
        self.heading: float | None = None
        self.relative = 0.0  # rad: that heading less the taught heading at the estimate, on the last view
        self.beside = 0.0  # m to the left of the taught path
        self.since = 0.0  # m driven since a view or the floor placed the robot

    def taught_heading(self, position: float) -> float:
        """The taught heading (rad) at ``position`` (subgoal units), between subgoals interpolated."""
        if self.taught is None or len(self.taught) < 2:
            return 0.0
        last = len(self.taught) - 1
        pos = min(max(position, 0.0), float(last))
        k = min(int(pos), last - 1)
        return float(self.taught[k] + (pos - k) * (self.taught[k + 1] - self.taught[k]))

    def view(self, position: float, matched: bool, floor: SideEstimate | None) -> None:
        """A view placed the estimate at ``position``; ``matched``: it matched a subgoal under its threshold;
        ``floor``: where the floor put the robot beside the path (None: it did not tell)."""
        if self.taught is None:
            return
        taught = self.taught_heading(position)
        if matched:
            self.heading, self.beside, self.since = taught, 0.0, 0.0
        elif floor is not None:  # its heading; the offset counts from here (a reading can be cm off)
            self.heading, self.beside, self.since = taught + floor.psi, 0.0, 0.0
        elif self.heading is None:  # the first view: nothing tells the heading yet, take the taught one
            self.heading = taught
        self.relative = self.heading - taught

    def commanded(self, v: float, w: float, dt: float) -> None:
        """The robot was commanded (v, w) for ``dt`` s (before the first view: nothing to count from)."""
        if self.heading is None:
            return
        self.beside += v * dt * math.sin(self.relative)
        self.heading += w * dt
        self.since += abs(v) * dt

    def judge(self) -> str | None:
        """What the commands spent beside the path past ``BESIDE_M`` (None: within it)."""
        if abs(self.beside) <= BESIDE_M:
            return None
        return (
            f"driven {self.since:.2f} m since a view or the floor last placed the robot, its commands took it "
            f"{abs(self.beside):.2f} m further to the {'left' if self.beside > 0 else 'right'} of the taught path"
        )


__all__ = ["BESIDE_M", "BesideWatch"]
