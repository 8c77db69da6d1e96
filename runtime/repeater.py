"""The repeat loop as an object: follow a taught route from camera images alone, one control step at a
time. The daemon (`vtr repeat`), the demo, the evaluation and the latency benchmark all run this class;
they differ only in the robot they hand it and in what they do with each :class:`StepRecord`.

One :meth:`Repeater.step`: validate the frame, let the controller judge it (it applies its own subgoal
switches and reports them as events), run the policy, apply its first (v, w) for dt, command zero unless
continuous. The decisions are the controller's (``runtime.controller``), the velocities the policy's.

Safety rules, in order of precedence:

- zero velocity is commanded when the run ends for any reason: finished, stalled, step limit, an
  interrupt (``stop_event`` or KeyboardInterrupt), a robot error, no valid frame in time, or any other
  exception (re-raised after the stop);
- a frame that fails validation (``BadFrameError`` from the client, or a wrong shape/dtype or a
  non-finite stamp from any Robot) is counted and never reaches the policy: the robot is stopped and
  re-polled with ``observe`` until a valid frame arrives, or ``frame_timeout_s`` passes without one;
- the step limit ends a run whose robot is lost.

How a run ends is a :class:`RepeatStatus`. Produced today: ``finished``, ``stalled`` (the controller's
stall guard), ``step_limit``, ``interrupted``, ``link_lost`` (no valid frame for ``frame_timeout_s``) and
``robot_error`` (a ``RobotError``). Reserved for the detectors that land next, and produced through the
two hooks below without touching this loop: ``lost`` (robust matching says the robot is off the route),
``collided`` and ``robot_restarted`` (the link sees a new server session).

- a terminal controller action whose value names a status (``Action.STALLED`` -> ``stalled``; a future
  ``Action("lost")`` -> ``lost``) ends the run with that status;
- a ``RobotError`` whose class attribute ``status`` names one (default ``robot_error``) ends it with
  that status, so a link can raise ``link_lost`` or ``robot_restarted``.
"""

from __future__ import annotations

import enum
import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from vtr.runtime.cliargs import opt
from vtr.runtime.contracts import CONTROL_DT, Observation, Policy, Robot
from vtr.runtime.controller import Action, Controller, ControllerConfig, Decision, Verdict
from vtr.runtime.protocol import BadFrameError
from vtr.runtime.robot import RobotError
from vtr.runtime.route import Route


class RepeatStatus(str, enum.Enum):
    """How a repeat ended (see the module docstring for which are produced today)."""

    FINISHED = "finished"  # past the last subgoal
    STALLED = "stalled"  # the stall guard found no subgoal close enough
    LOST = "lost"  # reserved: matching says the robot is off the route
    COLLIDED = "collided"  # reserved: the robot reports a collision
    ROBOT_RESTARTED = "robot_restarted"  # reserved: the robot's session changed under us
    LINK_LOST = "link_lost"  # no valid frame within frame_timeout_s
    INTERRUPTED = "interrupted"  # stop_event or KeyboardInterrupt
    STEP_LIMIT = "step_limit"  # max_steps commands sent
    ROBOT_ERROR = "robot_error"  # the robot cannot be reached or refused a command


@dataclass
class RepeatConfig:
    """Repeat-loop settings."""

    #: Subgoal switching (Algorithm 1 and its extensions).
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    #: Seconds each command is applied for; None takes the model's metadata dt (the paper's 0.1 s).
    dt: float | None = None
    #: Control steps (commands sent) before giving up: a lost robot must stop.
    max_steps: int = opt(2000, "stop after this many control steps (a lost robot must stop)")
    #: Seconds without a valid frame before the run ends.
    frame_timeout_s: float = opt(5.0, "seconds without a valid frame before stopping", flag="--frame-timeout")
    #: Pause between re-polls after a bad frame, in seconds.
    bad_frame_backoff_s: float = 0.05

    def __post_init__(self) -> None:
        if self.dt is not None and not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {self.dt!r}")
        if self.max_steps < 1:
            raise ValueError(f"--max-steps must be >= 1, got {self.max_steps}")
        if not self.frame_timeout_s > 0:
            raise ValueError(f"--frame-timeout must be > 0 seconds, got {self.frame_timeout_s}")
        if self.bad_frame_backoff_s < 0:
            raise ValueError(f"bad_frame_backoff_s must be >= 0, got {self.bad_frame_backoff_s}")


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
    None only when the run ended before any valid frame.
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
            "error": round(self.error, 4),
            "e_m": round(self.e_m, 4),
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


class _NoValidFrame(Exception):
    pass


def safe_stop(robot: Robot) -> bool:
    """Command zero velocity; never raises (the robot may be the thing that failed)."""
    try:
        robot.stop()
        return True
    except Exception:
        return False


def _status_of(value: str, default: RepeatStatus) -> RepeatStatus:
    try:
        return RepeatStatus(value)
    except ValueError:
        return default


class Repeater:
    """Follow ``route`` with ``policy`` on ``robot`` (see the module docstring).

    ``controller`` defaults to a fresh ``Controller(route.images, config.controller)``. ``on_step`` is
    called with every record :meth:`step` returns, the terminal one included. ``stop_event`` set from
    another thread (a signal handler) ends the run at the next step with a zero command.
    """

    def __init__(
        self,
        robot: Robot,
        policy: Policy,
        route: Route,
        controller: Controller | None = None,
        *,
        config: RepeatConfig | None = None,
        on_step: Callable[[StepRecord], None] | None = None,
        stop_event: threading.Event | None = None,
    ) -> None:
        self.config = config or RepeatConfig()
        self.robot, self.policy, self.route = robot, policy, route
        check = getattr(policy, "check_route", None)
        if check is not None:
            check(route)
        elif tuple(route.images.shape[1:3]) != tuple(policy.image_shape):
            raise ValueError(
                f"route images are {route.images.shape[1:3]} but the policy takes {policy.image_shape}"
            )
        model_dt = getattr(getattr(policy, "meta", None), "dt", None)
        if model_dt is not None and not math.isclose(float(route.dt), float(model_dt), rel_tol=1e-6):
            raise ValueError(
                f"the route was taught with dt = {route.dt} s but the model was trained for dt = {model_dt} s; "
                "teach the route again with the model's dt"
            )
        self.dt = float(self.config.dt if self.config.dt is not None else (model_dt or CONTROL_DT))
        self.controller = controller or Controller(route.images, self.config.controller)
        # one view object per subgoal, passed again while it is steered to (OnnxPolicy keeps its tensor)
        self._views = list(self.controller.subgoals)
        self._last = len(self._views) - 1
        self.on_step = on_step
        self.stop_event = stop_event or threading.Event()
        self.max_steps = self.config.max_steps
        self.steps = 0
        self.bad_frames = 0
        self.status: RepeatStatus | None = None
        self.detail = ""
        self._expect = (*route.images.shape[1:3], 3)
        self._obs: Observation | None = None
        self._first_stamp: float | None = None
        self._t_start: float | None = None
        self._wall_s = 0.0
        self._last_valid = 0.0
        self._last_rejected = ""
        self._totals: dict[str, float] = {}
        self._crashed = False

    @property
    def done(self) -> bool:
        return self.status is not None or self._crashed

    # ------------------------------------------------------------------ frames
    def _valid(self, obs: Observation) -> bool:
        image = obs.image
        if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.shape != self._expect:
            shape = getattr(image, "shape", None)
            kind = getattr(image, "dtype", type(image).__name__)
            self._last_rejected = f"image {shape} {kind}, expected {self._expect} uint8"
        elif not math.isfinite(obs.stamp):
            self._last_rejected = f"non-finite stamp {obs.stamp}"
        else:
            return True
        self.bad_frames += 1
        return False

    def _fetch(self, call: Callable[[], Observation]) -> Observation:
        """A valid frame from ``call``, else stop the robot and re-poll observe() until the deadline."""
        while True:
            try:
                obs = call()
                if self._valid(obs):
                    self._last_valid = time.monotonic()
                    return obs
            except BadFrameError as exc:
                self.bad_frames += 1
                self._last_rejected = str(exc)
            safe_stop(self.robot)
            if time.monotonic() - self._last_valid > self.config.frame_timeout_s or self.stop_event.is_set():
                raise _NoValidFrame()
            time.sleep(self.config.bad_frame_backoff_s)
            call = self.robot.observe

    # ------------------------------------------------------------------ the loop
    def step(self) -> StepRecord:
        """One control step (or the end of the run: then ``record.status`` is set and the robot stopped)."""
        if self.done:
            raise RuntimeError(f"the repeat has ended ({self.status.value if self.status else 'crashed'})")
        try:
            record = self._step()
        except _NoValidFrame:
            if self.stop_event.is_set():
                record = self._end(RepeatStatus.INTERRUPTED)
            else:
                detail = f"no valid frame for {self.config.frame_timeout_s} s; last rejected: {self._last_rejected}"
                record = self._end(RepeatStatus.LINK_LOST, detail)
        except RobotError as exc:
            record = self._end(_status_of(getattr(exc, "status", ""), RepeatStatus.ROBOT_ERROR), str(exc))
        except KeyboardInterrupt:
            record = self._end(RepeatStatus.INTERRUPTED)
        except BaseException:
            self._crashed = True
            safe_stop(self.robot)
            raise
        if self.on_step is not None:
            self.on_step(record)
        return record

    def _step(self) -> StepRecord:
        if self._obs is None:
            self._t_start = time.perf_counter()
            self._last_valid = time.monotonic()
            self._obs = self._fetch(self.robot.observe)
            self._first_stamp = self._obs.stamp
        obs = self._obs
        if self.stop_event.is_set():
            return self._end(RepeatStatus.INTERRUPTED)
        t0 = time.perf_counter()
        verdict = self.controller.judge(obs.image)
        t_error = time.perf_counter()
        decision = verdict.decision
        if decision.action is not Action.COMMAND:
            status = _status_of(decision.action.value, RepeatStatus.STALLED)
            return self._end(status, decision.note if status is not RepeatStatus.FINISHED else "", verdict)
        if self.steps >= self.max_steps:
            return self._end(RepeatStatus.STEP_LIMIT, "", verdict)
        velocities = self.policy.predict(obs.image, self._views[min(self.controller.index, self._last)])
        v, w = float(velocities[0, 0]), float(velocities[1, 0])
        t_policy = time.perf_counter()
        stage = dict(getattr(self.policy, "last_timing_ms", None) or {})
        stage["error"] = (t_error - t0) * 1e3
        stage["policy"] = (t_policy - t_error) * 1e3
        stage["compute"] = (t_policy - t0) * 1e3
        new_obs = self._fetch(lambda: self.robot.step(v, w, self.dt))
        # the robot's own breakdown of the step round trip (SimClient: receive, decode)
        robot_stage = getattr(self.robot, "last_timing_ms", None) or {}
        if decision.then_stop:
            self.robot.stop()
        t_end = time.perf_counter()
        stage["robot"] = (t_end - t_policy) * 1e3
        stage.update({k: float(x) for k, x in robot_stage.items()})
        stage["total"] = (t_end - t0) * 1e3
        for k, x in stage.items():
            self._totals[k] = self._totals.get(k, 0.0) + x
        record = self._record(verdict, obs, v, w, True, stage)
        self.steps += 1
        self._obs = new_obs
        return record

    def _record(
        self,
        verdict: Verdict | None,
        obs: Observation | None,
        v: float,
        w: float,
        commanded: bool,
        stage: Mapping[str, float],
        status: RepeatStatus | None = None,
        detail: str = "",
    ) -> StepRecord:
        index = self.controller.index
        return StepRecord(
            step=self.steps,
            from_subgoal=verdict.from_index if verdict is not None else index,
            subgoal=verdict.decision.index if verdict is not None else index,
            action=verdict.decision.action if verdict is not None else None,
            events=verdict.events if verdict is not None else (),
            error=verdict.decision.error if verdict is not None else math.nan,
            e_m=self.controller.e_m,
            v=v,
            w=w,
            commanded=commanded,
            stamp=obs.stamp if obs is not None else None,
            pose=obs.pose if obs is not None else None,
            latency_ms=stage,
            image=obs.image if obs is not None else None,
            status=status,
            detail=detail,
        )

    def _end(self, status: RepeatStatus, detail: str = "", verdict: Verdict | None = None) -> StepRecord:
        safe_stop(self.robot)
        self.status, self.detail = status, detail
        self._wall_s = time.perf_counter() - self._t_start if self._t_start is not None else 0.0
        return self._record(verdict, self._obs, 0.0, 0.0, False, {}, status, detail)

    def run(self, max_steps: int | None = None) -> Summary:
        """Step until the run ends (at most ``max_steps`` commands; default ``config.max_steps``)."""
        if max_steps is not None:
            if max_steps < 0:
                raise ValueError(f"max_steps must be >= 0, got {max_steps}")
            self.max_steps = max_steps
        while not self.done:
            self.step()
        return self.summary()

    def summary(self) -> Summary:
        """How the run ended (call once it has)."""
        if self.status is None:
            raise RuntimeError("the repeat has not ended yet")
        last = self._obs.stamp if self._obs is not None else None
        steps = self.steps
        return Summary(
            status=self.status,
            detail=self.detail,
            subgoals_reached=min(self.controller.index, len(self.controller)),
            subgoals_total=len(self.controller),
            steps=steps,
            e_m=self.controller.e_m,
            sim_time_s=(last - self._first_stamp)
            if last is not None and self._first_stamp is not None
            else 0.0,
            wall_time_s=self._wall_s,
            bad_frames=self.bad_frames,
            nonfinite_outputs=int(getattr(self.policy, "nonfinite_count", 0)),
            jumps=self.controller.jumps,
            localised_to=self.controller.localised_to,
            plateaus=self.controller.plateaus,
            mean_latency_ms={k: round(x / steps, 4) for k, x in self._totals.items()} if steps else {},
        )
