"""A taught turn in place ends where the floor shows the robot facing as the teach did at the turn's end.

In a taught turn in place the follower replays the taught turn until the views place the robot past its end.
Where they do not (dev house random:992, seed 1: the estimate held at 69.5-69.99 of 70 while the robot passed
the taught heading, every view of the turn's end 0.35 or more from its subgoal's, threshold 0.15), the replay
turned whole turns on the spot until the no-progress watch ended the run ``lost``; held-out set 45's gen_2719
(seed 1) did so at the route's start. Bounding the replay by the turn commanded (session 28, three versions)
stalled robots started off the route, whose heading is not the commanded turn's.

The floor the teach saw at the turn's end, registered as the side offset is (``SideOffset.estimate`` at that
subgoal: the far rows shift with the heading), tells the robot's heading against the taught one there to about
a degree, wherever the robot stands near the pivot. Open loop on development routes (71 turns of gen_106-179,
49 of houses random:900-959; headings 25 deg either way, robots up to 8 cm beside the pivot): no reading put a
robot 4 deg or more short of the end at or past it, and within a degree of it 96-100% (paper house) and 61-82%
(houses, where some floors tell nothing) read there. Where the floor places the heading at the end or past it
(short by no more than half the last command's turn, as the end's arrival judges a distance), the turn is
over: the belief moves to the end's subgoal (``RouteLocaliser.at_least``) and the robot drives on as the teach
did, VelocityNet correcting what heading is left. Where the floor does not tell, the replay goes on as before.
"""

from __future__ import annotations

import numpy as np

from vtr.runtime.frame import Frame
from vtr.runtime.side_offset import SideOffset


class TurnEnd:
    """Whether the floor shows a taught turn in place turned to its end (see the module docstring)."""

    def __init__(
        self, registration: SideOffset | None, motion: np.ndarray, held: np.ndarray, still: np.ndarray
    ) -> None:
        """``registration``: the route's floor (None: none, and every turn ends where the views place it);
        ``motion``: (L-1, 2) the taught motion of each gap (``kinematics.taught_motion``); ``held``: (L,)
        whether the teach turned in place into each subgoal; ``still``: (L,) whether the taught command out of
        each subgoal had no translation (a turn goes on where the teach turned on with no translation
        commanded but its pose moved, dev house random:939 at 120 deg: 9 mm and 2.4 deg more after the held
        ones)."""
        self.registration = registration
        n = len(held) if registration is not None else 0
        turn = np.asarray(motion, dtype=np.float64).reshape(-1, 2)[:, 1]
        #: per subgoal turned into: the subgoal where its turn ends, a drive after it (else -1: a final turn,
        #: which the end's own rules judge)
        self.end_of = np.full(n, -1)
        #: per subgoal of a turn (its start too): the taught turn left from it to the turn's end (rad, signed:
        #: left positive)
        self.left = np.zeros(n)
        for j in range(1, n):
            if not held[j] or held[j - 1]:
                continue
            start, end = j - 1, j
            while end < n - 1 and (held[end + 1] or still[end] and turn[end] != 0):
                end += 1
            self.left[start : end + 1] = np.cumsum(turn[start:end][::-1])[::-1].tolist() + [0.0]
            if end < n - 1:
                self.end_of[j : end + 1] = end
        self.reach = 0.0 if registration is None else registration.cfg.max_shift_rad

    def witness(self, view: Frame | np.ndarray, position: float, turn_step: float) -> int | None:
        """The end's subgoal of the taught turn in place that the estimate ``position`` is in, where the floor
        shows the robot turned to it or past it (short by at most half of ``turn_step``, the last command's
        turn in radians); None where it is not in such a turn, the turn left is beyond the registration's
        reach, or the floor does not show that."""
        gap = int(position)
        end = int(self.end_of[gap + 1]) if 0 <= gap + 1 < len(self.end_of) else -1
        if end < 0 or self.registration is None:
            return None
        left = self.left[gap] + (position - gap) * (self.left[gap + 1] - self.left[gap])  # still to turn
        if abs(left) > self.reach:  # the end's floor is beyond what the registration searches
            return None
        found = self.registration.estimate(view, float(end))
        if found is None:
            return None
        short = found.psi if self.left[gap] < 0 else -found.psi  # the heading short of the end (rad)
        return end if short <= 0.5 * abs(turn_step) else None


__all__ = ["TurnEnd"]
