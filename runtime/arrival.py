"""The route's end on the floor's evidence: the floor the teach saw at the last subgoal, registered along the
route as well as across it, places the robot at (or past) the last taught pose.

Why the views alone are not enough there: the localiser's grid ends at the last subgoal and a view from past
it looks like one from as far short of it, so the estimate stays about half a gap short while the robot drives
on; where a wall was re-textured or furniture moved, no view near the end matches under its threshold either
(held-out set 23: robots passed within 2-11 mm of the last pose and drove on 14-56 mm, or into moved
furniture). The floor near the robot is seen at known distances (``runtime.floor_view``): a robot ``dx``
short of the pose sees the taught floor rows ``dx`` further ahead, a shift of pixels per centimetre on the
nearest rows (``SideOffset.along``). The robot has arrived when stopping now leaves it no further from the pose
than one more control step would: ``dx`` at least minus half the last command's travel (or past the pose).
"""

from __future__ import annotations

import numpy as np

from vtr.runtime.progress_watch import END_ZONE_GAPS, PAST_END_M, route_left, taught_translation
from vtr.runtime.side_offset import SideOffset


class FloorArrival:
    """Whether the floor places the robot at the last taught pose (see the module docstring)."""

    def __init__(self, registration: SideOffset, motion: np.ndarray, held: np.ndarray) -> None:
        """``motion``: (L-1, 2) the taught motion of each gap (``kinematics.taught_motion``); ``held``: (L,)
        whether the teach turned in place into each subgoal (into the last one, the floor is not asked)."""
        self.registration = registration
        self.route_m = taught_translation(motion)
        self.past_m = max(abs(float(motion[-1, 0])), PAST_END_M)
        self.turns_at_end = bool(held[-1])
        # the end's floor checked once, with the route: whether it tells a distance along it
        self.end_tells = registration.tells_along(len(registration.poses) - 1)

    @classmethod
    def of(cls, registration: SideOffset | None, motion: np.ndarray, held: np.ndarray) -> FloorArrival | None:
        """The floor arrival of a route with a floor registration and a gap at least, else None."""
        return None if registration is None or len(motion) < 1 else cls(registration, motion, held)

    def judge(self, view: np.ndarray, position: float, step_m: float) -> tuple[bool, str] | None:
        """Whether the floor places the robot at the last taught pose, and where (FINISHED's evidence); None
        where it does not tell: short of the end's zone (``END_ZONE_GAPS``: the estimate can lag more than a gap
        behind a robot passing the end, held-out set 24's gen_2021 at 81.4 of 83), a floor that does not match,
        or a turn in place into the end (there the floor's offset along and beside is off by centimetres: dev
        gen_158, moved furniture, +39 mm along with the robot 75 mm from the pose; gen_176, +31 mm with it 3 mm
        from it). Arrived only where no offset that puts the robot short matches nearly as well
        (``SideConfig.along_margin``): where offsets centimetres apart match about as well, the best of them is
        where noise put it (dev house random:970: "finished" 73 mm short). ``position``: the localiser's
        estimate; ``step_m``: the last command's travel (m)."""
        last = len(self.registration.poses) - 1
        if self.turns_at_end or position < last - END_ZONE_GAPS:
            return None
        spacing = self.registration.along_step
        short = max(route_left(self.route_m, position), 0.0) + self.past_m
        # arrived: stopping now leaves the robot no further from the pose than one more step would
        least = -0.5 * abs(step_m)
        candidates = np.arange(-short, self.past_m + spacing / 2, spacing)
        found = self.registration.along(view, last, candidates, rivals_below=least)
        if found is None:
            return None
        along, beside = found.dx * 1e3, found.dy * 1e3
        where = f"the floor places the robot {along:+.0f} mm along, {beside:+.0f} mm beside the end"
        # and no offset short of that nearly as good: where one is, the floor cannot tell that it has arrived
        clear = found.margin >= self.registration.cfg.along_margin
        return clear and found.dx >= least, where

    def view_may_end(self, position: float, step_m: float) -> bool:
        """Whether a view that matches the last subgoal may end the run at the localiser's ``position``: always
        where the end's floor tells a distance along the route (the floor ends such runs; the view stands in
        for a view whose floor did not match) or the teach turned into the end; where it tells none, only
        once the estimate leaves no more of the route than half the last command's travel (``step_m``), the
        floor's own rule. There the view alone decides, and on a fast last stretch it matches under its
        threshold half a gap short (dev house random:959: "finished" 52 mm short, the estimate 0.62 gaps
        short); the estimate, which weighs the views with the commanded motion, places the robot better."""
        return self.turns_at_end or self.end_tells or route_left(self.route_m, position) <= 0.5 * abs(step_m)


__all__ = ["FloorArrival"]
