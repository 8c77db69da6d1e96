"""Whether a repeat still has evidence of where it is along the route and of getting on along it: the estimate
progressing, or, for a robot that stands, a view matching a subgoal. Without them for too long the follower
ends the run LOST (``runtime.follower``).

Too long is measured three ways, one state: images without progress or a match end a crawl (moved furniture
near the end: dev runs hunted back and forth 2 cm from the end, or stood 33 cm past it with the estimate half
a gap short, until the step limit); commanded translation without progress, a view matching or not, ends a
drive: past the taught travel across the localiser's window, a robot that had moved along the route would
have left every view the localiser compares with (held-out set 14, gen_1514: a fine-tuned model drove 1.9 m
at 0.25 m/s from near the route's end into a wall, its view 2.5-3x the threshold off, the estimate held at 46
of 49; the example room's arc with the floor model crept on 10 cm past the end, its view matching the
last-but-one subgoal at every image), and near the end past what the route had left: there is nothing past
the end for the views to follow (dev house random:935 at an 80 deg / 0.45 m camera: the robot passed 2 mm from
the last pose, the estimate held 1.2 gaps short, and it drove 0.27 m on into a wall within one window's
travel). Turning in place does not count: it sweeps no new floor, and robots
that turned a full circle looking for the view found it and finished (dev gen_109, gen_113: 0.0-0.02 m
driven in 100 images without evidence; the dev runs that touched something drove 1.1-1.2 windows' travel
blind); and images without new ground, views matching or not, end a stand or a rocking back and forth at one
place (``STAND_WINDOWS``): progress is the estimate passing the furthest it has been, so advancing again over
a stretch a matching view placed the robot back on does not count twice.
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
#: The images a robot may go without reaching new ground along the route (``PROGRESS_GAPS`` past the furthest
#: the estimate has been), views matching or not, in the units of ``STALL_WINDOWS``: a matching view lets a
#: robot stand where the views place it, not stand there for ever, nor rock back and forth over a stretch it
#: has covered (held-out house random:8046: the view matched subgoal 29 at a taught turn, the estimate held at
#: 28.5 and the robot stood 280 images to the step limit; set 12's gen_1317 on a wall-clock robot rocked at a
#: turn in place for 750 steps, each advance to 101 after a match placed it back at 100 counting as progress).
#: On dev houses 900-999 runs that finished went at most 101 images so; at an 80 deg / 0.20 m camera one spun
#: about 550 at a taught turn in place before a view matched (random:923), which now ends `lost`.
STAND_WINDOWS = 16.0
#: How far past the last taught pose the end's evidence still reaches (m): the floor registration searches at
#: least this far past it (runtime.arrival, runtime.pivot): a robot a control step past it at 0.45 m/s and
#: 0.1 s (the fastest taught segments) is 4.5 cm on. No robot drives further past the end without the views
#: following (:meth:`ProgressWatch.judge`).
PAST_END_M = 0.05


class ProgressWatch:
    """Counts images and commanded translation since the last evidence of where the robot is."""

    def __init__(self, window_images: float, route_m: np.ndarray | None = None) -> None:
        """``window_images``: the images the teach took for the localiser's window; ``route_m``: (L,) the
        taught translation from the first subgoal to each (:func:`taught_translation`): near the end no more
        than the route has left may be driven without progress (:meth:`judge`)."""
        self.stall_images = max(1, int(round(STALL_WINDOWS * window_images)))
        self.stand_images = max(1, int(round(STAND_WINDOWS * window_images)))
        self.route_m = None if route_m is None else np.asarray(route_m, dtype=np.float64)
        steps = np.diff(self.route_m) if self.route_m is not None else np.zeros(0)
        #: a gap's taught translation (the median of those that drive): the estimate's lag behind a robot
        #: driving past the end is about half of one (``EndWatch``)
        self.gap_m = float(np.median(steps[steps > 1e-6])) if (steps > 1e-6).any() else 0.0
        self.reset()

    def reset(self) -> None:
        """Count afresh (a new start, the robot held for something in the way)."""
        self.reach, self.since, self.travel = -math.inf, 0, 0.0
        # new ground: the furthest the estimate has reached, and the images since it did
        self.furthest, self.quiet = -math.inf, 0

    def commanded(self, v: float, dt: float) -> None:
        """The robot was commanded ``v`` (m/s, either way) for ``dt`` seconds."""
        self.travel += abs(v) * dt

    def judge(self, position: float, matched: bool, window_m: float) -> str | None:
        """One view: ``position`` the estimate, ``matched`` whether a subgoal matched the view, ``window_m``
        the taught travel across the localiser's window there. None while evidence is recent enough, else
        what was spent without it."""
        if position >= self.furthest + PROGRESS_GAPS:
            self.furthest, self.quiet = position, 0
        else:
            self.quiet += 1
        if self.quiet >= self.stand_images:  # matched or not: stood, or rocked over ground already covered
            return f"no progress past {self.furthest:.2f} for {self.quiet} images, views matching or not"
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
        # nor past the route's end: what is left of the route from the furthest the views placed the robot, a
        # gap for the estimate's lag and the reach of the end's floor registration past the last pose
        # (PAST_END_M) is all that can be driven without the views following
        known = self.route_m is not None and math.isfinite(self.reach)
        left = route_left(self.route_m, self.reach) if known else math.inf  # type: ignore[arg-type]
        if self.travel > left + self.gap_m + PAST_END_M:
            return (
                f"no progress past {self.reach:.2f} over {self.travel:.2f} m driven (the route had {left:.2f} m "
                "left)"
            )
        return None


def taught_translation(motion: np.ndarray) -> np.ndarray:
    """(L,) the taught translation (m, either way) from the first subgoal to each, from the (L-1, 2) taught
    motion of each gap (``kinematics.taught_motion``): the ``route_m`` the floor's registrations place along."""
    return np.concatenate([[0.0], np.cumsum(np.abs(motion[:, 0]))])


def route_left(route_m: np.ndarray, position: float) -> float:
    """What ``route_m`` (L,: cumulative from the first subgoal to each) has left from ``position`` (subgoal
    units, between subgoals interpolated) to the last subgoal."""
    last = len(route_m) - 1
    if last < 1:
        return 0.0
    k = min(max(int(math.floor(position)), 0), last - 1)
    frac = min(max(position - k, 0.0), 1.0)
    here = route_m[k] + frac * (route_m[k + 1] - route_m[k])
    return float(route_m[last] - here)


def final_turn_start(held: np.ndarray) -> int:
    """The subgoal where a route's final turn in place starts (``held``: (L,) whether the teach turned in place
    into each subgoal); the last subgoal where the route ends driving."""
    start = len(held) - 1
    while start > 0 and held[start]:
        start -= 1
    return start


#: The end's zone (gaps before the last subgoal): a view that matched a subgoal in it is the evidence that the
#: robot came to the end along the route, which the end by travel needs (``EndWatch``).
END_ZONE_GAPS = 2.0


class EndWatch:
    """Motion commanded since the views first placed the robot at the route's end, against what the taught
    route had left from there: past it, the robot drives (or turns) beyond the route's end, where nothing was
    taught.

    The localiser's grid ends at the last subgoal, and a view from past the end looks like one from as far
    short of it, so the estimate stays short of the end while the robot drives on (held-out set 15, gen_1617:
    the estimate held at 113.4-113.6 of 114 while the robot went from 7 mm to 51 mm past the last taught pose
    with the view never under the last threshold). The commanded motion is the evidence the views cannot
    give there, once a view has matched a subgoal in the end's zone (``END_ZONE_GAPS``): a robot whose views
    matched nothing near the end may be anywhere (dev gen_117, re-coloured floor: 0.32 m from the end, every
    view 1.4-1.9 thresholds off, the estimate carried to the end by the commanded motion), and the follower's
    other rules judge it as before.

    Motion is counted along the route as the localiser counts it (``RouteLocaliser.travel``: a turn at
    ``turn_length_m`` a radian, projected on the taught motion where the robot is), so a route that ends with
    a turn in place ends when the taught turn has been turned: there the views can stop matching too (a
    changed light or wall), the belief stays short of the end and a robot replaying the taught turn spun
    whole turns on the spot (dev gen_176, moved furniture: 3 mm from the end, passing the taught heading with
    the view 0.47 against 0.40, then turning a full circle until lost). The whole of such a turn is at the
    end's place, so the end's zone starts where the turn starts."""

    def __init__(self, route_m: np.ndarray, motion: np.ndarray, held: np.ndarray | None = None) -> None:
        """``route_m``: (L,) the taught travel (m, a turn counted at the localiser's ``turn_length_m`` a radian:
        ``RouteLocaliser.travelled``) from the first subgoal to each; ``motion``: (L-1, 2) the taught motion of
        each gap (m, rad: for the evidence's wording); ``held``: (L,) whether the teach turned in place into
        each subgoal (the end's zone starts where a final turn in place starts, where that is further back)."""
        self.route_m = np.asarray(route_m, dtype=np.float64)
        parts = np.abs(np.asarray(motion, dtype=np.float64).reshape(-1, 2))
        self._parts = np.concatenate([np.zeros((1, 2)), np.cumsum(parts, axis=0)])  # translation, turn
        last = len(self.route_m) - 1
        turn_from = last if held is None else final_turn_start(held)
        self.zone_from = min(last - END_ZONE_GAPS, float(turn_from))
        self.driven = 0.0  # along the route (``route_m``'s units)
        self.drove = self.turned = 0.0  # translation (m) and turn (rad) commanded, either way
        self.reset()

    def reset(self) -> None:
        self.start: float | None = None  # ``driven`` when the views first placed the robot at the end
        self.left = 0.0  # the taught travel left from there (``route_m``'s units)
        self._started = (0.0, 0.0)  # ``drove`` and ``turned`` then
        self._left_parts = (0.0, 0.0)  # the taught translation (m) and turn (rad) left then
        self.matched = False  # a view matched a subgoal in the end's zone

    def commanded(self, v: float, w: float, dt: float, along: float) -> None:
        """The robot was commanded (v, w) for ``dt`` seconds, which covers ``along`` of the route (``route_m``'s
        units, either way: ``RouteLocaliser.travel``)."""
        self.driven += along
        self.drove += abs(v) * dt
        self.turned += abs(w) * dt

    def left_from(self, position: float) -> float:
        """The taught travel (``route_m``'s units) from ``position`` (subgoal units) to the last subgoal."""
        return route_left(self.route_m, position)

    def judge(self, position: float, at_end: bool, matched: bool) -> str | None:
        """One view: ``at_end`` whether the views place the robot at the end, ``matched`` whether the view matched
        a subgoal under its threshold. None while the robot has gone no further than the taught route had left
        when the views first placed it at the end (after a match in the end's zone), else what it did."""
        if position < self.zone_from:  # back along the route: count afresh at the end
            self.reset()
            return None
        self.matched = self.matched or matched
        if self.start is None:
            if not (at_end and self.matched):
                return None
            self.start, self.left = self.driven, self.left_from(position)
            self._started = (self.drove, self.turned)
            self._left_parts = (
                route_left(self._parts[:, 0], position),
                route_left(self._parts[:, 1], position),
            )
        if self.driven - self.start <= self.left:
            return None
        m, turn = self.drove - self._started[0], self.turned - self._started[1]
        left_m, left_turn = self._left_parts
        return (
            f"drove {m:.2f} m and turned {math.degrees(turn):.0f} deg since the views placed it at the route's "
            f"end (the route had {left_m:.2f} m and {math.degrees(left_turn):.0f} deg left)"
        )


__all__ = [
    "END_ZONE_GAPS",
    "PROGRESS_GAPS",
    "STALL_WINDOWS",
    "EndWatch",
    "ProgressWatch",
    "final_turn_start",
    "route_left",
    "taught_translation",
]
