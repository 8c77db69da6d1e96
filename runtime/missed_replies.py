"""Step replies that keep missing their wait: a robot too slow for the control period.

A reply that comes later than the step's duration + the link's timeout is missed (``runtime.robot.MissedReply``:
the client stops the robot and the repeat re-polls it), so a robot that always answers just too late would be
stopped after every command and creep on until the step limit. :class:`MissedReplies` counts the misses in a row
and says when there were enough to end the run as ``robot_too_slow``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from vtr.runtime.robot import MissedReply

T = TypeVar("T")


class MissedReplies:
    """Motion commands in a row whose reply missed its wait; ``limit`` of them (0: never) mean too slow."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.in_row = 0
        self.total = 0
        self.wait_s = 0.0

    def watch(self, call: Callable[[], T]) -> Callable[[], T]:
        """``call`` (a step) counted: a MissedReply adds one (and is raised on), any answer resets the count."""

        def watched() -> T:
            try:
                out = call()
            except MissedReply as exc:
                self.in_row += 1
                self.total += 1
                self.wait_s = exc.wait_s
                raise
            self.in_row = 0
            return out

        return watched

    @property
    def too_slow(self) -> bool:
        return self.limit > 0 and self.in_row >= self.limit

    def describe(self, dt: float) -> str:
        """The run's detail when it ends for this."""
        margin = self.wait_s - dt
        return (
            f"robot too slow for the control period: the last {self.in_row} step replies missed their "
            f"{self.wait_s:.2f} s wait (the {dt:.2f} s step + {margin:.2f} s for the reply) and the robot was "
            "stopped after each; a robot that is slow but sound needs a longer --timeout"
        )
