"""A taught turn in place starts where the floor places the robot at the turn's pose, not where the views do.

The localiser's views tell a gap of the route only as finely as neighbouring subgoals differ, and a turn in
place is held (no translation) from the moment the estimate reaches the subgoal where the teach stopped to
turn. On a fast stretch (gaps of 8 cm) the estimate can get there a gap early: dev house random:931 turned 77 mm
short of its final turn, and every view of the turn, facing a plain wall, matched as well there as at the
pose (`finished` 77 mm from the end). The floor the teach saw at that subgoal, registered along the route as
the end's arrival does (``runtime.arrival``, ``SideOffset.along``), tells how far short of the pose the robot
is. Where it places the robot short by more than half a control step, that is an observation of the
localiser (``RouteLocaliser.observe``): the belief moves back, the robot drives on toward the pose, and the
turn starts when the estimate reaches it again and the floor agrees, or does not tell. Once a turn has
started, its pose is not asked again (a turned view is no registration along the route), nor after the robot
has driven on the search's whole span since the floor first placed it short.
"""

from __future__ import annotations

import math

import numpy as np

from vtr.runtime.frame import Frame
from vtr.runtime.localiser import RouteLocaliser
from vtr.runtime.progress_watch import PAST_END_M, taught_translation
from vtr.runtime.side_offset import SideOffset

#: How far short of the turn's pose the floor is searched: this many of the wider of the two gaps driven into it.
SHORT_GAPS = 1.5
#: The observation's spread (gaps): the registration is good to a centimetre or two, a quarter of a gap.
OBSERVED_STD = 0.25


class PivotArrival:
    """Where the floor places the robot short of a taught turn in place's pose (see the module docstring)."""

    def __init__(self, registration: SideOffset | None, motion: np.ndarray, held: np.ndarray) -> None:
        """``registration``: the route's floor (None: none, and every turn starts where the estimate gets to it,
        as on a route with no turn in place after a drive); ``motion``: (L-1, 2) the taught motion of each gap
        (``kinematics.taught_motion``); ``held``: (L,) whether the teach turned in place into each subgoal."""
        self.registration = registration
        n = len(held) if registration is not None else 0
        drive = np.abs(motion[:, 0])
        #: per gap: the subgoal where the teach stopped driving to turn in place (the turn's pose), else -1
        self.pivot_of = np.full(n, -1)
        for k in range(1, n - 1):
            if held[k + 1] and not held[k] and drive[k - 1] > 1e-3:
                j = k + 1
                while j < n and held[j]:
                    self.pivot_of[j - 1] = k
                    j += 1
        self._route_m = taught_translation(motion)
        before = np.concatenate([[0.0], drive])[: len(drive)]  # the gap before each
        self._span = SHORT_GAPS * np.maximum(drive, before)  # searched short of each gap's end (m)
        self._done: set[int] = set()  # turns started (or given up on): not asked again
        # per turn's pose: the translation (m) commanded since the floor placed the robot short of it
        self._driven: dict[int, float] = {}

    def place(
        self, view: Frame | np.ndarray, gap: int, step_m: float, localiser: RouteLocaliser
    ) -> int | None:
        """Where the estimate is in gap ``gap`` of a taught turn in place: the turn's pose (a subgoal) if the floor
        places the robot short of it, after weighing ``localiser``'s belief by where; else None, and the turn
        starts (its pose is not asked again)."""
        placed = self.short_of(view, gap, step_m)
        if placed is None:
            self.started(gap)
            return None
        localiser.observe(placed, OBSERVED_STD)
        return int(math.ceil(placed))

    def short_of(self, view: Frame | np.ndarray, gap: int, step_m: float) -> float | None:
        """The route position (subgoal units) the floor places the robot at, where the estimate is in gap ``gap``
        of a taught turn in place whose pose the floor places the robot short of (by more than half of
        ``step_m``, the last command's translation); None where it is not short, the floor does not tell, or the
        turn's pose was judged before."""
        k = self._pose(gap)
        if k < 0 or k in self._done or self.registration is None:
            return None
        span = float(self._span[k - 1])
        if self._driven.get(k, 0.0) > span:  # drove the search's span on: the reading is not borne out
            self._done.add(k)
            return None
        spacing = self.registration.along_step
        least = -0.5 * abs(step_m)
        ahead = np.arange(-span - spacing, PAST_END_M + spacing / 2, spacing)
        # a place, not only "short": the best offset must score under every other (two or more steps from it),
        # those past the pose too (dev gen_166, moved furniture: placed 23-30 mm short, with no rival short of
        # that in the search, of a pose the robot stood 6-13 mm from)
        found = self.registration.along(view, k, ahead)
        if found is None or found.margin < self.registration.cfg.along_margin or found.dx >= least:
            return None
        self._driven.setdefault(k, 0.0)
        at = self._route_m[k] + found.dx  # the taught translation to where the floor places the robot
        return float(np.interp(at, self._route_m[: k + 1], np.arange(k + 1)))

    def commanded(self, v: float, dt: float) -> None:
        """The robot was told to drive ``v`` for ``dt``: counted toward every pose the floor placed it short of."""
        for k in self._driven:
            self._driven[k] += abs(v) * dt

    def started(self, gap: int) -> None:
        """The turn in place of gap ``gap`` has started: its pose is not asked again."""
        if (k := self._pose(gap)) >= 0:
            self._done.add(k)

    def _pose(self, gap: int) -> int:
        """The turn's pose of gap ``gap`` (-1: not a taught turn in place after a drive)."""
        return int(self.pivot_of[gap]) if 0 <= gap < len(self.pivot_of) else -1

    def reset(self) -> None:
        """Every turn is asked again (a relocalised robot may come to them anew)."""
        self._done.clear()
        self._driven.clear()


__all__ = ["OBSERVED_STD", "SHORT_GAPS", "PivotArrival"]
