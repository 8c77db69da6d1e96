"""The repeat loop as an object: follow a taught route from camera images alone, one control step at a
time. The daemon (`vtr repeat`), the demo, the evaluation and the latency benchmark all run this class;
they differ only in the robot they hand it and in what they do with each :class:`StepRecord`.

One :meth:`Repeater.step`: check the observation (its frame was checked once, where it was made), let the
controller judge the frame (``runtime.follower`` by default: where the robot is and which subgoal to steer to;
its subgoal changes come back as events), run the policy, take off its command on the subgoal itself (the zero
bias, computed once per subgoal when the route is loaded), blend in the taught command (the controller's
feed-forward), clip to the model's and the robot's limits, let the range scan's zones stop or slow it
(``runtime.safety``), apply that (v, w) for dt, command zero unless continuous.

Safety rules, in order of precedence:

- zero velocity is commanded when the run ends for any reason: finished, stalled, step limit, an
  interrupt (``stop_event`` or KeyboardInterrupt), a robot error, no valid frame in time, or any other
  exception (re-raised after the stop);
- a frame that fails validation (``BadFrameError`` from the client, or a wrong shape/dtype or a non-finite
  stamp from any Robot), the reply to the zero command between steps included, is counted and never reaches
  the policy: the robot is stopped and re-polled with ``observe`` until a valid frame arrives, or
  ``frame_timeout_s`` passes without one; ``missed_replies`` step replies in a row too late end the run;
- the step limit ends a run whose robot is lost.

How a run ends is a :class:`RepeatStatus` (its docstring lists when each is produced). Something in the way
(the range scan's stop zone, or the controller's BLOCKED from the camera) holds the robot with zero steps until
it clears, or ends the run as ``blocked`` after ``RepeatConfig.wait_s``.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Mapping

import numpy as np

from vtr.runtime.contracts import CONTROL_DT, Observation, Policy, Robot
from vtr.runtime.controller import Action, Verdict
from vtr.runtime.follower import RouteController, controller_for_route
from vtr.runtime.frame import frames_of
from vtr.runtime.missed_replies import MissedReplies
from vtr.runtime.protocol import BadFrameError
from vtr.runtime.repeat_types import RepeatConfig, RepeatStatus, StepRecord, Summary
from vtr.runtime.robot import RobotError, safe_stop
from vtr.runtime.route import Route
from vtr.runtime.safety import limit_twist, taught_zones, travel_ahead

__all__ = ["RepeatConfig", "RepeatStatus", "Repeater", "StepRecord", "Summary", "safe_stop"]


#: Restarts a run re-localises after (``localise``); one more ends it as robot_restarted.
MAX_RELOCALISATIONS = 3


class _NoValidFrame(Exception):
    pass


def _status_of(value: str, default: RepeatStatus) -> RepeatStatus:
    try:
        return RepeatStatus(value)
    except ValueError:
        return default


class Repeater:
    """Follow ``route`` with ``policy`` on ``robot`` (see the module docstring).

    ``controller`` defaults to a fresh ``Controller.for_route(route, config.controller)``. ``on_step`` is
    called with every record :meth:`step` returns, the terminal one included. ``stop_event`` set from
    another thread (a signal handler) ends the run at the next step with a zero command.
    """

    def __init__(
        self,
        robot: Robot,
        policy: Policy,
        route: Route,
        controller: RouteController | None = None,
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
        self.controller = (
            controller if controller is not None else controller_for_route(route, self.config.controller)
        )
        # one frame per subgoal, passed again while it is steered to (the policy keeps its tensor on it)
        self._views = frames_of(self.controller.subgoals)
        self._last = len(self._views) - 1
        self._bias = self._self_bias(self.controller.cfg.zero_bias)
        self._ahead = travel_ahead(route.travel_poses())  # the zones bend where the route turns in place
        # the tightest bounds of the model and of what the robot announced: the zero bias and the taught prior
        # can take a command past the network's own (a command past the robot's is refused, ending the run)
        bounds = [
            b for b in (getattr(policy, "meta", None), getattr(robot, "limits", None)) if hasattr(b, "v_max")
        ]
        self._v_max = min([math.inf, *(float(b.v_max) for b in bounds)])
        self._w_max = min([math.inf, *(float(b.w_max) for b in bounds)])
        self.on_step = on_step
        self.stop_event = stop_event or threading.Event()
        self.max_steps = self.config.step_limit(len(route))
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
        #: Robot restarts survived by re-localising (``localise`` only).
        self.robot_restarts = 0
        #: Zero steps held while something was in the way; when the current wait began (robot clock, wall).
        self.waited_steps = 0
        self._blocked_since: tuple[float, float] | None = None
        self._missed = MissedReplies(self.config.missed_replies)  # step replies too late, in a row

    def _self_bias(self, weight: float) -> np.ndarray | None:
        """(L, 2) ``weight * policy(S, S)`` per subgoal S, or None when off: what the network commands with the
        robot already on the subgoal, taken off every command toward it (ControllerConfig.zero_bias)."""
        if weight <= 0:
            return None
        predict = self.policy.predict
        return weight * np.array([np.asarray(predict(view, view), np.float64)[:2, 0] for view in self._views])

    @property
    def done(self) -> bool:
        return self.status is not None or self._crashed

    # ------------------------------------------------------------------ frames
    def _valid(self, obs: Observation) -> bool:
        """Whether ``obs`` carries a frame of the route's size and a finite stamp (its frame checked once: by
        the robot adapter that made it, else here; nothing after this checks it again)."""
        try:
            shape = obs.frame.shape
        except BadFrameError as exc:
            self._last_rejected = str(exc)
        else:
            if shape != self._expect:
                self._last_rejected = f"image {shape} uint8, expected {self._expect} uint8"
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
            self._zero()
            if time.monotonic() - self._last_valid > self.config.frame_timeout_s or self.stop_event.is_set():
                raise _NoValidFrame()
            time.sleep(self.config.bad_frame_backoff_s)
            call = self.robot.observe

    def _zero(self) -> None:
        """The zero command, re-sent while its reply is bad (each one counted as a bad frame) until one is
        good or ``frame_timeout_s`` passes: after a bad reply the robot gets nothing but stops. A lost link
        or a restarted robot (RobotError) ends the step like any other."""
        while True:
            try:
                self.robot.stop()
                return
            except BadFrameError as exc:
                self.bad_frames += 1
                self._last_rejected = str(exc)
                if (
                    time.monotonic() - self._last_valid > self.config.frame_timeout_s
                    or self.stop_event.is_set()
                ):
                    raise _NoValidFrame() from None
                time.sleep(self.config.bad_frame_backoff_s)

    def _relocalise(self, why: str) -> StepRecord:
        """``localise``: the robot restarted; stop it, then find the route again on its next frame."""
        safe_stop(self.robot)
        self.robot_restarts += 1
        self.controller.relocalise()
        self._obs = None  # the next step fetches a fresh frame from the rebooted robot
        return self._record(None, None, 0.0, 0.0, False, {}, None, f"{why}; re-localising on the next frame")

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
            status = _status_of(getattr(exc, "status", ""), RepeatStatus.ROBOT_ERROR)
            relocalise = self.controller.cfg.localise and self.robot_restarts < MAX_RELOCALISATIONS
            if status is RepeatStatus.ROBOT_RESTARTED and relocalise:
                record = self._relocalise(str(exc))
            else:
                record = self._end(status, str(exc))
        except KeyboardInterrupt:
            record = self._end(RepeatStatus.INTERRUPTED)
        except BaseException:
            self._crashed = True
            safe_stop(self.robot)
            raise
        if self.on_step is not None:
            try:
                self.on_step(record)
            except BaseException:  # the observer failed (a full disk, Ctrl-C in it): the robot stops first
                self._crashed = True
                safe_stop(self.robot)
                raise
        return record

    def _step(self) -> StepRecord:
        if self._obs is None:
            self._t_start = self._t_start or time.perf_counter()
            self._last_valid = time.monotonic()
            self._obs = self._fetch(self.robot.observe)
            self._first_stamp = self._obs.stamp
        obs = self._obs
        if self.stop_event.is_set():
            return self._end(RepeatStatus.INTERRUPTED)
        if self._missed.too_slow:  # each step was stopped already; another would only creep on
            return self._end(RepeatStatus.ROBOT_TOO_SLOW, self._missed.describe(self.dt))
        t0 = time.perf_counter()
        verdict = self.controller.judge(obs.frame, obs.collided)
        t_error = time.perf_counter()
        decision = verdict.decision
        if decision.action is Action.BLOCKED:  # the camera sees the way ahead blocked
            return self._wait(obs, verdict, decision.note)
        if decision.action is not Action.COMMAND:
            status = _status_of(decision.action.value, RepeatStatus.STALLED)
            return self._end(status, decision.note, verdict)  # a FINISHED note is its evidence
        if self.steps >= self.max_steps:
            return self._end(RepeatStatus.STEP_LIMIT, "", verdict)
        target = min(self.controller.index, self._last)
        velocities = self.policy.predict(obs.frame, self._views[target])
        v, w = float(velocities[0, 0]), float(velocities[1, 0])
        if self._bias is not None:
            v, w = v - float(self._bias[target, 0]), w - float(self._bias[target, 1])
        a, b, pv, pw = decision.prior or (0.0, 0.0, 0.0, 0.0)  # the taught command blended in, and the
        v, w = (1 - a) * v + a * pv, (1 - b) * w + b * pw + decision.turn  # follower's side correction
        v, w = v * self.config.speed, w * self.config.speed  # the same arc, slower
        v_max = min(decision.v_limit, self._v_max)  # v_limit 0: no translation in a taught turn in place
        v, w = max(-v_max, min(v_max, v)), max(-self._w_max, min(self._w_max, w))
        zones = taught_zones(self.config.safety, self.route.clearance, target, self._ahead)
        guard = limit_twist(v, w, obs.scan, zones)  # stop / slow for what the range scan shows
        if guard.blocked:
            return self._wait(obs, verdict, guard.describe())
        v, w = guard.v, guard.w
        self._blocked_since = None
        t_policy = time.perf_counter()
        stage = dict(getattr(self.policy, "last_timing_ms", None) or {})
        stage["error"] = (t_error - t0) * 1e3
        stage["policy"] = (t_policy - t_error) * 1e3
        stage["compute"] = (t_policy - t0) * 1e3
        new_obs = self._fetch(self._missed.watch(lambda: self.robot.step(v, w, self.dt)))
        self.controller.commanded(v, w, self.dt)  # the progress gate counts what the robot was told
        # the robot's own breakdown of the step round trip (SimClient: receive, decode)
        robot_stage = getattr(self.robot, "last_timing_ms", None) or {}
        if decision.then_stop:
            self._zero()
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

    def _wait(self, obs: Observation, verdict: Verdict, evidence: str) -> StepRecord:
        """Something is in the way: hold still with a zero step (so that a lockstep robot's clock runs and a
        new frame comes) until the way clears, or end as ``blocked`` after ``wait_s`` (the robot's clock once
        it has moved: a lockstep simulator's runs with the steps, slower than the wall on a loaded machine;
        the wall clock while it stands still, so that a robot whose clock is stuck still ends)."""
        now = (float(obs.stamp), time.monotonic())
        since = self._blocked_since = self._blocked_since or now
        waited = now[0] - since[0] if now[0] > since[0] else now[1] - since[1]
        if waited >= self.config.wait_s:
            return self._end(RepeatStatus.BLOCKED, f"{evidence}; waited {waited:.1f} s", verdict)
        new_obs = self._fetch(self._missed.watch(lambda: self.robot.step(0.0, 0.0, self.dt)))
        self.controller.commanded(0.0, 0.0, self.dt)
        self.waited_steps += 1
        detail = f"{evidence}; waiting up to {self.config.wait_s:g} s"
        record = self._record(verdict, obs, 0.0, 0.0, False, {}, None, detail, waited)
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
        waited_s: float | None = None,
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
            waited_s=waited_s,
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
            robot_restarts=self.robot_restarts,
            waited_steps=self.waited_steps,
            mean_latency_ms={k: round(x / steps, 4) for k, x in self._totals.items()} if steps else {},
        )
