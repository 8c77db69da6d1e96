"""The contracts every package shares, defined once: the robot's limits and control step, the camera,
the observation, and the Policy / Robot / Simulator protocols that type the seams between packages.

Lean on purpose (numpy and the standard library only): the robot board imports it, and so do the
simulator, training and export, which take their defaults from here instead of repeating the numbers.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple, Protocol, runtime_checkable

import numpy as np

from vtr.runtime.frame import Frame, as_frame
from vtr.runtime.scan import Scan

#: The paper's robot: |v| <= 0.5 m/s (Twist linear.x), |w| <= 1.0 rad/s (angular.z).
V_MAX = 0.5
W_MAX = 1.0
#: Seconds each command is applied for: the paper's control step, the teach recording period and the
#: spacing of training frames.
CONTROL_DT = 0.1
#: The simulated robot's footprint: a disc of this radius (m); the safety layer's default size.
ROBOT_RADIUS = 0.17


@dataclass(frozen=True)
class RobotLimits:
    """Velocity bounds of a differential-drive robot (REP-103 axes)."""

    v_max: float = V_MAX  # m/s
    w_max: float = W_MAX  # rad/s


@dataclass(frozen=True)
class CameraSpec:
    """The forward camera the shipped model was trained with (the simulator renders exactly this)."""

    width: int = 128  # pixels (the network's input)
    height: int = 128  # pixels
    fov_deg: float | None = 90.0  # horizontal field of view, square pixels (None: unknown)
    height_m: float | None = 0.3  # optical centre above the floor (None: unknown)


#: Defaults, one source: sim2d.CameraConfig, training's image sizes and the model metadata start here.
LIMITS = RobotLimits()
CAMERA = CameraSpec()


class Pose(NamedTuple):
    """Planar pose in the world frame (REP-103): metres, radians, yaw counter-clockwise from +x."""

    x: float
    y: float
    yaw: float


@dataclass(frozen=True)
class Observation:
    """One camera frame.

    image: (H, W, 3) uint8 RGB (as a checked :class:`~vtr.runtime.frame.Frame`: :attr:`frame`). stamp: the
    robot's clock in seconds (simulated time for the simulator). pose: ground-truth (x, y, yaw) in
    metres/radians when the other side knows it, else None (the repeat never uses it; evaluation scores with
    it). collided: the robot touched something on the way. scan: the range reading taken with the image, when
    the robot has a scanner (None: camera only). twist: the (v, w) the robot reports it executed, when its hello
    announces ``twist`` (None: not reported); whoever commanded it (this runtime or the robot's own joystick:
    `vtr teach --follow`).
    """

    image: np.ndarray
    stamp: float
    pose: tuple[float, float, float] | None = None
    collided: bool = False
    scan: Scan | None = None
    twist: tuple[float, float] | None = None

    @functools.cached_property
    def frame(self) -> Frame:
        """``image`` as a checked frame: the one the robot adapter made with the observation (:meth:`of_frame`:
        the client's decoder, the in-process simulator), else made from ``image`` on first use (a plain array
        from a test or a tool: checked then, a ``BadFrameError`` saying what is wrong)."""
        return as_frame(self.image)

    @classmethod
    def of_frame(cls, frame: Frame, stamp: float, **fields: Any) -> Observation:
        """An observation of a frame made where the image entered (its ``image`` is the frame's)."""
        obs = cls(frame.image, stamp, **fields)
        obs.__dict__["frame"] = frame  # the cached property's value: the frame is not made again
        return obs


@runtime_checkable
class Policy(Protocol):
    """Images in, velocities out: what the repeat loop steers with (``runtime.policy.OnnxPolicy``).

    Optional attributes the repeat loop reads when present: ``meta`` (``ModelMeta``: its ``dt``),
    ``last_timing_ms`` (stage durations of the last call), ``nonfinite_count`` (outputs replaced by a
    zero command) and ``check_route(route)`` (refuse a route the model cannot use).
    """

    @property
    def image_shape(self) -> tuple[int, int]:
        """(H, W) of the images ``predict`` takes."""
        ...

    def predict(self, current: Frame, subgoal: Frame) -> np.ndarray:
        """Current and subgoal frames (``frame.image``: (H, W, 3) uint8) -> (2, N): row 0 v (m/s), row 1 w
        (rad/s). The repeat loop passes :class:`~vtr.runtime.frame.Frame` s; ``OnnxPolicy`` also takes arrays."""
        ...


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
    """A robot that can be placed at a pose (a simulator); used by `vtr teach` and the evaluation."""

    def reset(self, pose: tuple[float, float, float] | None = None, seed: int | None = None) -> Observation:
        """Place the robot at ``pose`` (None: the map's default start) and return the first frame."""
        ...


@runtime_checkable
class Simulator(Protocol):
    """What the simulator server and ``LocalRobot`` drive (``sim2d.Simulator``, or a test double).

    Images are (H, W, 3) uint8; ``time`` is simulated seconds; ``collided`` refers to the last step.
    """

    @property
    def pose(self) -> Any:  # anything with .x, .y, .yaw (a Pose)
        ...

    @property
    def time(self) -> float: ...

    @property
    def collided(self) -> bool: ...

    def reset(self, pose: Pose | None = None, seed: int | None = None) -> np.ndarray: ...

    def observe(self) -> np.ndarray: ...

    def step(self, v: float, w: float, duration: float) -> np.ndarray: ...

    def info(self) -> Mapping[str, Any]:
        """Camera, limits, map name and clock, as plain data (the server's hello reply carries it)."""
        ...
