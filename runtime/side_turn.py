"""The turn back toward the taught path from the side offset the floor shows (``runtime.side_offset``): a pure
pursuit of the path point ``side_lookahead`` ahead, ``side_gain`` x atan(dy / side_lookahead) rad/s (see
``ControllerConfig``), at most ``SIDE_TURN_MAX``, ``dy`` the median of the last ``SIDE_VIEWS`` views' estimates.

VelocityNet lines the view up with the subgoal's, which closes a side offset only over a few wall distances of
travel; the follower (``runtime.follower``) adds this turn (``Decision.turn``) where the teach and the robot
drive forward and the floor tells.
"""

from __future__ import annotations

import math

from vtr.runtime.side_offset import SideEstimate

#: The most the side correction turns (rad/s): VelocityNet keeps the rest of the turn range, and holds a
#: heading toward the path of this / 3.6 rad (16 deg; 0.5, 8 deg, left 10 cm starts 3 cm off after 1 m).
SIDE_TURN_MAX = 1.0
#: The side turn follows the median of this many floor estimates of views in a row while driving: one view's
#: estimate can be wrong by centimetres (just after a turn in place, the taught floor warped to a pose the
#: localiser has a little off), and a pursuit acts on it at any pace.
SIDE_VIEWS = 3


class SideTurn:
    """The pursuit's turn, view by view, from the floor's side estimates of the views in a row that told one."""

    def __init__(self, gain: float, lookahead: float) -> None:
        self.gain, self.lookahead = gain, lookahead
        #: Where the floor put the robot beside the taught path on the last view (None: it did not tell).
        self.beside: SideEstimate | None = None
        self.run: list[float] = []  # the side offsets of the last views in a row the floor told

    def turn(self, found: SideEstimate | None) -> float:
        """The turn (rad/s) for a view whose floor estimate is ``found`` (None: not asked, or the floor did not
        tell: the run of views starts afresh); none until SIDE_VIEWS views in a row told one."""
        self.beside = found
        if found is None:
            self.run.clear()
            return 0.0
        self.run.append(found.dy)
        del self.run[:-SIDE_VIEWS]
        if len(self.run) < SIDE_VIEWS:
            return 0.0
        dy = sorted(self.run)[len(self.run) // 2]
        turn = -self.gain * math.atan(dy / self.lookahead)
        return max(-SIDE_TURN_MAX, min(SIDE_TURN_MAX, turn))


__all__ = ["SIDE_TURN_MAX", "SIDE_VIEWS", "SideTurn"]
