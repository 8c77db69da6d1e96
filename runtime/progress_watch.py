"""Whether a repeat still has evidence of where it is along the route and of getting on along it: the estimate
progressing, or, for a robot that stands, a view matching a subgoal. Without them for too long the follower
ends the run LOST (``runtime.follower``).

Too long is measured two ways, one state: images without progress or a match end a crawl (moved furniture
near the end: dev runs hunted back and forth 2 cm from the end, or stood 33 cm past it with the estimate half
a gap short, until the step limit); commanded translation without progress, a view matching or not, ends a
drive: past the taught travel across the localiser's window, a robot that had moved along the route would
have left every view the localiser compares with (held-out set 14, gen_1514: a fine-tuned model drove 1.9 m
at 0.25 m/s from near the route's end into a wall, its view 2.5-3x the threshold off, the estimate held at 46
of 49; the example room's arc with the floor model crept on 10 cm past the end, its view matching the
last-but-one subgoal at every image). Turning in place does not count: it sweeps no new floor, and robots
that turned a full circle looking for the view found it and finished (dev gen_109, gen_113: 0.0-0.02 m
driven in 100 images without evidence; the dev runs that touched something drove 1.1-1.2 windows' travel
blind).
"""

from __future__ import annotations

import math

import numpy as np

#: The estimate has progressed when it moves this far (gaps) past the furthest it reached: one cell of the
#: localiser's grid moves by noise alone.
PROGRESS_GAPS = 0.25
#: The images a robot may go without evidence, in units of the images the teach took for the localiser's
#: whole window of subgoals (8: 128 images on a route taught a subgoal every 2 steps). On dev routes runs that
#: finished went at most 15 images so, one 108 (moved furniture, closing in on the end); runs that never would
#: finish 220-734, until the step limit (``benchmarks/results/ending_s5.md``).
STALL_WINDOWS = 8.0


class ProgressWatch:
    """Counts images and commanded translation since the last evidence of where the robot is."""

    def __init__(self, window_images: float) -> None:
        """``window_images``: the images the teach took for the localiser's window."""
        self.stall_images = max(1, int(round(STALL_WINDOWS * window_images)))
        self.reset()

    def reset(self) -> None:
        """Count afresh (a new start, the robot held for something in the way)."""
        self.reach, self.since, self.travel = -math.inf, 0, 0.0

    def commanded(self, v: float, dt: float) -> None:
        """The robot was commanded ``v`` (m/s, either way) for ``dt`` seconds."""
        self.travel += abs(v) * dt

    def judge(self, position: float, matched: bool, window_m: float) -> str | None:
        """One view: ``position`` the estimate, ``matched`` whether a subgoal matched the view, ``window_m``
        the taught travel across the localiser's window there. None while evidence is recent enough, else
        what was spent without it."""
        if position >= self.reach + PROGRESS_GAPS:
            self.reach, self.since, self.travel = position, 0, 0.0
            return None
        if matched:  # the view says where the robot is: it may stand there, not drive on without progress
            self.reach, self.since = min(self.reach, position), 0
        else:
            self.since += 1
        if self.since >= self.stall_images:
            return f"no progress past {self.reach:.2f} for {self.since} images"
        if self.travel > window_m:
            return (
                f"no progress past {self.reach:.2f} over {self.travel:.2f} m driven (the window spans "
                f"{window_m:.2f} m)"
            )
        return None


#: The end's zone (gaps before the last subgoal): a view that matched a subgoal in it is the evidence that the
#: robot came to the end along the route, which the end by travel needs (``EndWatch``).
END_ZONE_GAPS = 2.0


class EndWatch:
    """Commanded translation since the views first placed the robot at the route's end, against what the taught
    route had left from there: past it, the robot drives beyond the route's end, where nothing was taught.

    The localiser's grid ends at the last subgoal, and a view from past the end looks like one from as far
    short of it, so the estimate stays short of the end while the robot drives on (held-out set 15, gen_1617:
    the estimate held at 113.4-113.6 of 114 while the robot went from 7 mm to 51 mm past the last taught pose
    with the view never under the last threshold). The commanded motion is the evidence the views cannot
    give there, once a view has matched a subgoal in the end's zone (``END_ZONE_GAPS``): a robot whose views
    matched nothing near the end may be anywhere (dev gen_117, re-coloured floor: 0.32 m from the end, every
    view 1.4-1.9 thresholds off, the estimate carried to the end by the commanded motion), and the follower's
    other rules judge it as before."""

    def __init__(self, route_m: np.ndarray) -> None:
        """``route_m``: (L,) the taught translation (m) from the first subgoal to each."""
        self.route_m = np.asarray(route_m, dtype=np.float64)
        self.driven = 0.0
        self.reset()

    def reset(self) -> None:
        self.start: float | None = None  # ``driven`` when the views first placed the robot at the end
        self.left = 0.0  # the taught translation left from there (m)
        self.matched = False  # a view matched a subgoal in the end's zone

    def commanded(self, v: float, dt: float) -> None:
        """The robot was commanded ``v`` (m/s, either way) for ``dt`` seconds."""
        self.driven += abs(v) * dt

    def left_from(self, position: float) -> float:
        """The taught translation (m) from ``position`` (subgoal units) to the last subgoal."""
        last = len(self.route_m) - 1
        if last < 1:
            return 0.0
        k = min(max(int(math.floor(position)), 0), last - 1)
        frac = min(max(position - k, 0.0), 1.0)
        here = self.route_m[k] + frac * (self.route_m[k + 1] - self.route_m[k])
        return float(self.route_m[last] - here)

    def judge(self, position: float, at_end: bool, matched: bool) -> str | None:
        """One view: ``at_end`` whether the views place the robot at the end, ``matched`` whether the view matched
        a subgoal under its threshold. None while the robot has driven no further than the taught route had
        left when the views first placed it at the end (after a match in the end's zone), else what it drove."""
        if position < len(self.route_m) - 1 - END_ZONE_GAPS:  # back along the route: count afresh at the end
            self.reset()
            return None
        self.matched = self.matched or matched
        if self.start is None:
            if not (at_end and self.matched):
                return None
            self.start, self.left = self.driven, self.left_from(position)
        beyond = self.driven - self.start
        if beyond <= self.left:
            return None
        return f"drove {beyond:.2f} m since the views placed it at the route's end ({self.left:.2f} m of route left)"


__all__ = ["END_ZONE_GAPS", "PROGRESS_GAPS", "STALL_WINDOWS", "EndWatch", "ProgressWatch"]
