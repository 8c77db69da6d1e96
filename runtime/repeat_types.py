"""What a repeat produces and how it is set up: :class:`RepeatStatus`, :class:`StepRecord`,
:class:`Summary` and :class:`RepeatConfig` (the loop itself is ``runtime.repeater.Repeater``)."""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from vtr.runtime.controller import Action, ControllerConfig, Decision
from vtr.runtime.safety import SafetyConfig


class RepeatStatus(str, enum.Enum):
    """How a repeat ended.

    Produced: ``finished``, ``stalled`` (the rules controller's stall guard), ``lost`` (no subgoal near the current one matches the view), ``collided`` (an observation
    reported a contact; the controller decides on ``Observation.collided``), ``blocked`` (something stayed
    in the way for ``RepeatConfig.wait_s``), ``step_limit``, ``interrupted``,
    ``link_lost`` (no valid frame for ``frame_timeout_s``, or the link's ``LinkLost``: no reply even to the stop
    sent after a missed one), ``robot_error`` (a ``RobotError``), ``robot_too_slow`` (``missed_replies`` step
    replies in a row came too late: ``runtime.missed_replies``) and ``robot_restarted``. ``robot_restarted``
    (the link saw a new server session: the robot rebooted and is somewhere else) ends the run, or with the
    controller's ``localise`` the robot is stopped and the route searched again on its next frame (at most
    ``MAX_RELOCALISATIONS`` times; the record's detail says so).

    - a terminal controller action whose value names a status (``Action.STALLED`` -> ``stalled``,
      ``Action.LOST`` -> ``lost``, ``Action.COLLIDED`` -> ``collided``) ends the run with that status;
    - a ``RobotError`` whose class attribute ``status`` names one (default ``robot_error``) ends it with
      that status, so a link can raise ``link_lost`` or ``robot_restarted``.
    """

    FINISHED = "finished"  # past the last subgoal
    STALLED = "stalled"  # the stall guard found no subgoal close enough
    LOST = "lost"  # no subgoal near the current one matches the view (the controller)
    COLLIDED = "collided"  # an observation reported a contact (the controller)
    BLOCKED = "blocked"  # something stayed in the way for wait_s (the range scan, or the camera)
    ROBOT_RESTARTED = "robot_restarted"  # the robot's session changed under us (it rebooted)
    LINK_LOST = "link_lost"  # no valid frame within frame_timeout_s
    INTERRUPTED = "interrupted"  # stop_event or KeyboardInterrupt
    STEP_LIMIT = "step_limit"  # max_steps commands sent
    ROBOT_ERROR = "robot_error"  # the robot cannot be reached or refused a command
    ROBOT_TOO_SLOW = "robot_too_slow"  # step replies kept missing their wait (RepeatConfig.missed_replies)


@dataclass
class RepeatConfig:
    """Repeat-loop settings."""

    #: Subgoal switching (Algorithm 1 and its extensions).
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    #: Seconds each command is applied for; None takes the model's metadata dt (the paper's 0.1 s).
    dt: float | None = None
    #: Control steps (commands sent) before giving up: a lost robot must stop. None: 8 per subgoal + 50,
    #: over ``speed``, so that it scales with the route (:meth:`step_limit`).
    max_steps: int | None = None
    #: Seconds without a valid frame before the run ends.
    frame_timeout_s: float = 5.0
    #: Pause between re-polls after a bad frame, in seconds.
    bad_frame_backoff_s: float = 0.05
    #: Stop and slowdown zones ahead of the robot, applied when the robot sends a range scan.
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    #: Seconds to wait for the way to clear when something is in it, before the run ends as ``blocked``.
    wait_s: float = 10.0
    #: Fraction of the commanded speed driven (taught pace, VelocityNet and limits alike): a careful first
    #: repeat at 0.5. The arc each command drives is the same; the route takes 1/speed the time.
    speed: float = 1.0
    #: Step replies missed in a row (no reply within the step + the link's timeout; the stop after each was
    #: answered) before the run ends as ``robot_too_slow``; 0: never.
    missed_replies: int = 10

    def step_limit(self, subgoals: int) -> int:
        """``max_steps``, or by default 8 per subgoal + 50 (4x the taught steps at 2 per subgoal) at full
        speed: a lost robot must stop, a long route must not be cut short."""
        return self.max_steps or math.ceil((8 * subgoals + 50) / self.speed)

    def __post_init__(self) -> None:
        if self.dt is not None and not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {self.dt!r}")
        if self.max_steps is not None and self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        if not self.frame_timeout_s > 0:
            raise ValueError(f"frame_timeout_s must be > 0 seconds, got {self.frame_timeout_s}")
        if not (math.isfinite(self.wait_s) and self.wait_s >= 0):
            raise ValueError(f"wait_s must be >= 0 seconds, got {self.wait_s}")
        if not (math.isfinite(self.speed) and 0 < self.speed <= 1):
            raise ValueError(f"speed must be in (0, 1], got {self.speed}")
        if self.missed_replies < 0:
            raise ValueError(f"missed_replies must be >= 0, got {self.missed_replies}")
        if self.bad_frame_backoff_s < 0:
            raise ValueError(f"bad_frame_backoff_s must be >= 0, got {self.bad_frame_backoff_s}")


def _finite(x: float) -> float | None:
    """A log number: rounded, or null where there is none (nan, inf: JSON has no such numbers)."""
    return round(x, 4) if math.isfinite(x) else None


@dataclass(frozen=True)
class StepRecord:
    """One judged image: the command sent on it, or how the run ended on it.

    ``step``: commands sent before this one. ``from_subgoal``/``subgoal``: the index before the image
    was judged and the one steered to; ``events``: the controller's ADVANCE/JUMP decisions on it;
    ``error``: the image error (0..255) to ``subgoal``; ``v``, ``w``: the command applied for dt (zero
    when ``commanded`` is False); ``pose``/``stamp``: the robot's pose (None when unknown) and clock of
    the image; ``latency_ms``: ``error`` (controller), ``preprocess``/``inference`` (policy stages),
    ``policy`` (predict), ``compute`` (image in to command ready), ``robot`` (step round trip plus the
    zero command) and what the robot reports itself (SimClient: ``receive``, ``decode``), ``total``.
    ``status`` is set on the record that ended the run (then no command was sent on it); ``image`` is
    None only when the run ended before any valid frame; ``waited_s`` is set while the way is blocked.
    """

    step: int
    from_subgoal: int
    subgoal: int
    action: Action | None
    events: tuple[Decision, ...]
    error: float
    e_m: float
    v: float
    w: float
    commanded: bool
    stamp: float | None
    pose: tuple[float, float, float] | None
    latency_ms: Mapping[str, float]
    image: np.ndarray | None
    status: RepeatStatus | None = None
    detail: str = ""
    waited_s: float | None = None  # seconds waited so far for a blocked way (None: not waiting)

    @property
    def advanced(self) -> int:
        return sum(1 for e in self.events if e.action is Action.ADVANCE)

    @property
    def jumped_to(self) -> list[int]:
        return [e.index for e in self.events if e.action is Action.JUMP]

    def to_log(self) -> dict[str, Any]:
        """The JSON-lines log record of a command (`vtr repeat --log`)."""
        return {
            "step": self.step,
            "subgoal": self.subgoal,
            "from_subgoal": self.from_subgoal,
            "advanced": self.advanced,
            "jumped_to": self.jumped_to,
            "error": _finite(self.error),
            "e_m": _finite(self.e_m),
            "v": self.v,
            "w": self.w,
            "stamp": self.stamp,
            "pose": list(self.pose) if self.pose is not None else None,
            "latency_ms": {k: round(x, 4) for k, x in self.latency_ms.items()},
        }


@dataclass(frozen=True)
class Summary:
    """How a repeat ended, with its counters."""

    status: RepeatStatus
    detail: str
    subgoals_reached: int
    subgoals_total: int
    steps: int
    e_m: float
    sim_time_s: float
    wall_time_s: float
    bad_frames: int
    nonfinite_outputs: int
    jumps: int
    localised_to: int | None
    plateaus: int = 0  # subgoals the stall guard accepted next to, at error <= jump_factor * e_m
    robot_restarts: int = 0  # restarts survived by re-localising (localise only)
    waited_steps: int = 0  # zero steps held while something was in the way
    mean_latency_ms: Mapping[str, float] = field(default_factory=dict)

    @property
    def completed(self) -> bool:
        return self.status is RepeatStatus.FINISHED

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["status"] = self.status.value
        out["completed"] = self.completed
        out["mean_latency_ms"] = dict(self.mean_latency_ms)
        return out
