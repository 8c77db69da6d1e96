"""The simulated robot's own joystick: a ROUTE.json played by the server itself (`vtr sim serve --drive-script`).

This is how `vtr teach --follow` is tried on the simulator: a robot driven by someone else, whom the teach only
watches. The server drives the script's segments on its own clock (realtime mode only: in lockstep nothing would
move between the teach's ``observe`` requests), starting with the first ``observe`` it answers (the follower's
first look), and stands still once the script ends. While the script runs the robot takes no motion command
from any client (``step`` and ``reset`` are refused, as a bridge whose operator holds the joystick would);
afterwards it is an ordinary robot again.
"""

from __future__ import annotations

import bisect
import itertools
import math

from vtr.runtime.route_script import RouteScript


class ScriptedDriver:
    """Which twist the joystick holds at each moment of simulated time since the script started."""

    def __init__(self, script: RouteScript) -> None:
        self.script = script
        #: Simulated seconds at which each segment ends.
        self.ends = list(itertools.accumulate(s.duration for s in script.segments))
        #: Simulated time (since the server's start) at which the script started; None: not yet.
        self.started: float | None = None

    def start(self, now: float) -> None:
        if self.started is None:
            self.started = now

    def holding(self, now: float) -> bool:
        """True from the server's start until the script has ended: the robot is not the clients' to move."""
        if self.started is None:
            return True
        return bool(self.ends) and now - self.started < self.ends[-1]

    def twist(self, now: float) -> tuple[float, float, float]:
        """(v, w, until): the twist held at simulated time ``now`` and the time it changes (inf: never)."""
        if self.started is None:
            return 0.0, 0.0, math.inf
        i = bisect.bisect_right(self.ends, now - self.started + 1e-12)
        if i >= len(self.ends):
            return 0.0, 0.0, math.inf
        seg = self.script.segments[i]
        return seg.v, seg.w, self.started + self.ends[i]
