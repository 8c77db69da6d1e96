"""What the repeat loop needs from a robot, and the error a robot raises.

The protocols and the observation live in ``runtime.contracts`` (one source); they are re-exported
here for the robot-side code that imports them by this name. ``runtime.client.SimClient`` implements
``Robot`` over ZeroMQ; ``sim2d.local_robot.LocalRobot`` wraps an in-process simulator for fast
evaluation; a real robot bridge implements it on the robot's side.
"""

from __future__ import annotations

from vtr.runtime.contracts import Observation, ResettableRobot, Robot
from vtr.runtime.wire_json import BadFrameError

__all__ = [
    "Interrupted",
    "safe_stop",
    "LinkLost",
    "MissedReply",
    "Observation",
    "ResettableRobot",
    "Robot",
    "RobotError",
    "RobotRestarted",
]


class RobotError(RuntimeError):
    """The robot cannot be reached or refused a command; the message says which and why.

    ``status`` is how a repeat that meets this error ends (a ``runtime.repeater.RepeatStatus`` value):
    a subclass for a lost link or a restarted robot sets ``"link_lost"`` or ``"robot_restarted"``.
    """

    status: str = "robot_error"


class RobotRestarted(RobotError):
    """The robot's session changed: it rebooted and no longer is where the run left it."""

    status = "robot_restarted"


class LinkLost(RobotError):
    """The robot did not answer, not even the zero command sent after the missed reply."""

    status = "link_lost"


class Interrupted(RobotError):
    """A wait for the robot was abandoned because the run was asked to stop (Ctrl-C, SIGTERM)."""

    status = "interrupted"


class MissedReply(BadFrameError):
    """No reply to a motion command within its wait (its duration + the link's timeout), while the stop sent
    after it was answered: the robot is there but answered too late, or not at all. The repeat counts these
    (``RepeatConfig.missed_replies``: enough in a row end it as ``robot_too_slow``)."""

    def __init__(self, message: str, wait_s: float) -> None:
        super().__init__(message)
        self.wait_s = wait_s


def safe_stop(robot: Robot) -> bool:
    """Command zero velocity; never raises (the robot may be the thing that failed)."""
    try:
        robot.stop()
        return True
    except Exception:
        return False
