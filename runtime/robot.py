"""What the daemon needs from a robot: an image with a stamp, and a way to move for a while and to stop.

``runtime.client.SimClient`` implements it over ZeroMQ; ``sim2d.local_robot.LocalRobot`` wraps an
in-process simulator for fast evaluation; a real robot bridge implements it on the robot's side.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


class RobotError(RuntimeError):
    """The robot cannot be reached or refused a command; the message says which and why."""


@dataclass(frozen=True)
class Observation:
    """One camera frame.

    image: (H, W, 3) uint8 RGB. stamp: the robot's clock in seconds (simulated time for the simulator).
    pose: ground-truth (x, y, yaw) in metres/radians when the other side knows it, else None.
    """

    image: np.ndarray
    stamp: float
    pose: tuple[float, float, float] | None = None
    collided: bool = False


@runtime_checkable
class Robot(Protocol):
    """A differential-drive robot with a forward camera. Velocities follow REP-103 (Twist linear.x, angular.z)."""

    def observe(self) -> Observation:
        """The current camera frame, without moving."""
        ...

    def step(self, v: float, w: float, duration: float) -> Observation:
        """Apply (v m/s, w rad/s) for ``duration`` seconds, then return the new frame."""
        ...

    def stop(self) -> None:
        """Command zero velocity."""
        ...


@runtime_checkable
class ResettableRobot(Robot, Protocol):
    """A robot that can be placed at a pose (a simulator); used by `vtr teach`."""

    def reset(self, pose: tuple[float, float, float] | None = None, seed: int | None = None) -> Observation:
        """Place the robot at ``pose`` (None: the map's default start) and return the first frame."""
        ...


class RobotRestarted(RobotError):
    """The robot's session changed: it rebooted and no longer is where the run left it."""


class LinkLost(RobotError):
    """The robot did not answer, not even the zero command sent after the missed reply."""


class Interrupted(RobotError):
    """A wait for the robot was abandoned because the run was asked to stop (Ctrl-C, SIGTERM)."""
