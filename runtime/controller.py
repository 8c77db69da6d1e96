"""Subgoal switching as a pure state machine: an image in, a decision out. No I/O and no model inside.

The paper's Algorithm 1, exactly, with ``ControllerConfig.paper()``::

    while i < l:
        error = mean |I_t - I_i|                  (0..255, at the model's resolution)
        if error > e_m:  COMMAND                  the daemon runs VelocityNet(I_t, I_i), applies the first
                                                  (v, w) for dt = 0.1 s, then commands zero
        else:            ADVANCE                  i += 1, and the same image is judged against I_{i+1}
    FINISHED

Beyond the paper, with ``switching="rules"`` (the release before the route localiser; the default controller is
now ``runtime.follower``, which steers from ``runtime.localiser``'s estimate instead), each rule switchable in
:class:`ControllerConfig`, whose field comments give the dev figures behind each default:

- **Matching** (``match``, runtime.matching): patch-normalised, median over tiles; ``raw`` is the paper's error.
- **Switch threshold** (``e_m_mode``): ``fixed`` (``e_m``), ``calibrated`` (one per route from the gaps between
  taught subgoals), ``per_subgoal`` (from each subgoal's incoming gap) or ``hybrid`` (the route's, raised where
  both neighbouring gaps are wide; the default). ``pass_ratio`` > 0 adds a relative switch (the next subgoal
  matches as well as the current one); ``settle_steps`` keeps steering while the error still falls.
- **Stall guard** (``stall_steps``, ``idle_steps``): after commands without progress, JUMP to a better subgoal
  ahead or accept a plateau within ``jump_factor`` thresholds (once per motion of the view), else STALLED.
- **Progress gate** (``progress_gate``, runtime.progress_gate): switch past a subgoal only after commanding that
  fraction of the taught travel into it.
- **Light ramp** (``match_ramp``), **taught prior** (``taught_prior``), **zero bias** (``zero_bias``, applied
  by the repeat loop), **turns in place** held at v = 0 (``hold_turns``), the raw error on **plain routes**.
- **Lost** (``lost_steps``): no subgoal near the current one matches for a while: LOST with the evidence.
- **Contact** (``stop_on_contact``): COLLIDED. **Start anywhere** (``localise``) and **continuous** mode.

These rules advance the subgoal without seeing the robot get there (the plateau, the stall guard's jumps, the
gate's patience): issue 19 measured boxes driven into and runs "finished" beside the route because of them,
which is why the follower replaced them as the default. They stay for ``--profile paper`` and for the ablation
(``vtr eval --suite conditions --controllers rules``); the matching study is ``studies/matching_study.py`` and
``python -m vtr.evaluation.trace_run`` traces a run against the true pose.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from vtr.runtime.controller_config import ControllerConfig
from vtr.runtime.decisions import SWITCHES, TERMINAL, Action, Decision, Verdict  # noqa: F401 - this module's API
from vtr.runtime.frame import Frame, as_frame
from vtr.runtime.light import remove_side_ramp
from vtr.runtime.progress_gate import ProgressGate
from vtr.runtime.thresholds import (  # noqa: F401 - calibrate_e_m, consecutive_errors: part of this API
    DEFAULT_BOUNDS,
    LOST_FLOOR,
    LOST_WINDOW,
    PLAIN_ROUTE_GAP,
    calibrate_e_m,
    check_subgoals,
    consecutive_errors,
    gaps_between,
    lost_bounds,
    route_views,
    thresholds,
)

#: A taught step that moved the robot less than this (m) is a turn in place (``hold_turns``).
HOLD_TOLERANCE_M = 0.005

if TYPE_CHECKING:
    from vtr.runtime.route import Route


class Controller:
    """Decide, image by image, whether to command, advance, jump, finish or stop (stalled, lost, collided)."""

    def __init__(
        self,
        subgoals: np.ndarray,
        cfg: ControllerConfig | None = None,
        commands: np.ndarray | None = None,
        poses: np.ndarray | None = None,
        travel_poses: np.ndarray | None = None,
    ) -> None:
        """``commands``: the taught (v, w) after each subgoal (``Route.commands``), for ``hold_turns``;
        ``poses``: the taught (x, y, yaw) (``Route.poses``), so that a subgoal the teach reached partly by
        translating is not held (a route keeps one subgoal every few control steps: the first command
        after subgoal i-1 can be the end of a turn and the next one a drive); ``travel_poses``: what the
        progress gate measures the taught travel by (default ``poses``; ``Route.travel_poses`` dead-reckons
        them from the commands for a route taught without poses)."""
        check_subgoals(subgoals)
        self.cfg = cfg or ControllerConfig()
        self.commands = None if commands is None else np.asarray(commands, dtype=np.float64).reshape(-1, 2)
        self._held = self.turns_in_place(self.commands, poses, len(subgoals))
        self.subgoals = subgoals
        n = len(subgoals)
        views = route_views(subgoals, self.cfg)
        self.cfg, self.matcher, self._feats, self.gaps = views.cfg, views.matcher, views.feats, views.gaps
        #: Set when the route is too plain for patch matching and the raw error is used instead.
        self.fallback, self.thresholds, self.median_gap = views.fallback, views.thresholds, views.median_gap
        self.lost_bound = views.lost_bound
        self._lost_bounds = lost_bounds(self.gaps, n, self.cfg, self.lost_bound)
        self.index = 0
        self.stalled = False
        self.status: Action | None = None  # the terminal action once the run stopped
        self.jumps = 0
        self.plateaus = 0  # subgoals the stall guard accepted next to, at error <= jump_factor * threshold
        self.early_switches = 0  # subgoals passed by the relative rule while above their threshold
        self.localised_to: int | None = None
        self._localise_pending = self.cfg.localise
        self._plateau_view: np.ndarray | None = None  # features of the view at the last plateau acceptance
        self._lost_count = 0
        self._view_of: np.ndarray | None = None
        self._view_index = -1
        self._view = np.empty(0)
        self.gate = None  # the progress gate: needs the taught poses (or a path dead-reckoned from commands)
        travel = poses if travel_poses is None else travel_poses
        if self.cfg.progress_gate > 0 and travel is not None and len(travel) >= n:
            self.gate = ProgressGate(travel, n, self.cfg.progress_gate, self.cfg.gate_patience)
        self._set_index(0)

    @classmethod
    def for_route(cls, route: Route, cfg: ControllerConfig | None = None) -> Controller:
        """The controller of a taught route: its subgoals, commands, poses and the travel the progress gate
        measures (``Route.travel_poses``, dead-reckoned where the route has no poses)."""
        return cls(route.images, cfg, route.commands, route.poses, route.travel_poses())

    def __len__(self) -> int:
        return int(self.subgoals.shape[0])

    @property
    def finished(self) -> bool:
        return self.index >= len(self)

    @property
    def e_m(self) -> float:
        """The threshold in force (of the current subgoal)."""
        return float(self.thresholds[min(self.index, len(self) - 1)])

    @property
    def subgoal(self) -> np.ndarray:
        """The current subgoal image (H, W, 3) uint8."""
        return self.subgoals[min(self.index, len(self) - 1)]

    def _set_index(self, index: int) -> None:
        self.index = index
        self._best = math.inf
        self._lost_best = math.inf
        self._no_progress = 0
        self._idle = 0  # commands in a row in which the policy hardly moved the robot
        self._last_error = math.inf
        self._settled = 0
        if self.gate is not None:
            self.gate.reset(index)

    def _may_pass(self, i: int) -> bool:
        return self.gate is None or self.gate.passes(i)

    def commanded(self, v: float, w: float, dt: float) -> None:
        """The repeat loop applied (v, w) for ``dt`` seconds (the progress gate and the idle rule count it)."""
        idle = abs(v) < self.cfg.idle_speed and abs(w) < self.cfg.idle_turn
        self._idle = self._idle + 1 if idle else 0
        if self.gate is not None:
            self.gate.commanded(v, w, dt)

    def _stop(self, action: Action, error: float, note: str) -> Decision:
        self.status = action
        self.stalled = action is Action.STALLED
        return Decision(action, self.index, error, note=note)

    def decide(self, image: Frame | np.ndarray, collided: bool = False) -> Decision:
        """One step of the state machine for ``image`` (a frame, or (H, W, 3) uint8 at the subgoals' resolution,
        checked here)."""
        image = as_frame(image, self.subgoals.shape[1:3])
        if self.finished:
            return Decision(Action.FINISHED, self.index, math.nan)
        if self.status is not None:
            return Decision(self.status, self.index, math.nan, note=f"{self.status.value} earlier")
        if collided and self.cfg.stop_on_contact:
            return self._stop(Action.COLLIDED, math.nan, f"contact reported at subgoal {self.index}")
        ramp = self.cfg.match_ramp and self.cfg.match.method == "patch"
        if image is not self._view_of or (ramp and self._view_index != self.index):
            seen = remove_side_ramp(image, self.subgoal) if ramp else image  # toward the subgoal judged
            self._view, self._view_of, self._view_index = self.matcher.features(seen), image, self.index
        view = self._view
        if self._localise_pending:
            self._localise_pending = False
            decision = self._localise(view)
            if decision is not None:
                return decision
        i = self.index
        error = self.matcher.distance(view, self._feats[i])
        threshold = self.thresholds[i]
        if self.cfg.pass_ratio > 0 and i + 1 < len(self) and error > threshold:
            nxt = self.matcher.distance(view, self._feats[i + 1])
            # only a real match counts (under the lost bound): two unrelated views score alike, and a
            # lost robot must not "pass" subgoals on noise
            if nxt <= self.cfg.pass_ratio * error and nxt < self.lost_bound and self._may_pass(i):
                self.early_switches += 1
                self._set_index(i + 1)
                return Decision(Action.ADVANCE, self.index, error, note="next subgoal matches as well")
        min_step = self.cfg.stall_min_improvement
        min_step = 0.02 * threshold if min_step is None else min_step
        improving = error < self._last_error - min_step
        self._last_error = error
        if error <= threshold:
            if improving and self._settled < self.cfg.settle_steps:
                self._settled += 1
                return self._command(i, error, note="settling")
            if not self._may_pass(i):
                return self._command(i, error, note="waiting for travel")
            self._set_index(i + 1)
            return Decision(Action.ADVANCE, self.index, error)
        if self.cfg.lost_steps > 0:
            lost = self._lost(view, error, min_step)
            if lost is not None:
                return lost
        if self.cfg.stall_steps > 0:
            if error < self._best - min_step:
                self._best = error
                self._no_progress = 0
            else:
                self._best = min(self._best, error)
                self._no_progress += 1
            if self._no_progress >= self.cfg.stall_steps:
                return self._unstall(view, error)
            if 0 < self.cfg.idle_steps <= self._idle:  # the policy is done here: do not wait for noise
                decision = self._unstall(view, error, stop=False)
                if decision is not None:
                    return decision
        return self._command(i, error)

    @staticmethod
    def turns_in_place(commands: np.ndarray | None, poses: np.ndarray | None, n: int) -> np.ndarray:
        """Per subgoal: did the taught robot reach it by turning on the spot? The command after subgoal
        i-1 had v = 0, and (where poses are known) the taught position moved under HOLD_TOLERANCE_M."""
        held = np.zeros(n, dtype=bool)
        if commands is None or len(commands) < n:
            return held
        held[1:] = commands[: n - 1, 0] == 0.0
        if poses is not None and len(poses) >= n:
            xy = np.asarray(poses, dtype=np.float64)[:n, :2]
            with np.errstate(invalid="ignore"):  # unknown (NaN) poses leave the command's verdict
                held[1:] &= ~(np.hypot(*np.diff(xy, axis=0).T) >= HOLD_TOLERANCE_M)
        return held

    def holds_turn(self, i: int) -> bool:
        """Whether commands toward subgoal ``i`` are held at v = 0 (``hold_turns``: a taught turn in place)."""
        return self.cfg.hold_turns and i < len(self._held) and bool(self._held[i])

    def _command(self, i: int, error: float, note: str = "") -> Decision:
        prior = None
        owed = self.gate is None or self.gate.progress < 1.0  # the taught gap is not yet driven
        if self.cfg.taught_prior > 0 and owed and self.commands is not None and 0 < i <= len(self.commands):
            prior = (self.cfg.taught_prior, self.cfg.taught_prior, *map(float, self.commands[i - 1]))
        return Decision(
            Action.COMMAND,
            i,
            error,
            then_stop=not self.cfg.continuous,
            note=note,
            v_limit=0.0 if self.holds_turn(i) else math.inf,
            prior=prior,
        )

    def judge(self, image: Frame | np.ndarray, collided: bool = False) -> Verdict:
        """Decide on ``image`` until a decision needs the robot: subgoal switches (ADVANCE, JUMP) are
        applied here and reported as events, so the caller handles only COMMAND and the terminal ones."""
        from_index, events = self.index, []
        image = as_frame(image, self.subgoals.shape[1:3])  # an array: checked once, not at every decide
        decision = self.decide(image, collided)
        while decision.action in SWITCHES:
            events.append(decision)
            decision = self.decide(image, collided)
        return Verdict(decision, tuple(events), from_index)

    def relocalise(self) -> None:
        """Search the whole route for the best-matching subgoal on the next image (after a robot restart)."""
        self._localise_pending = True

    def _lost(self, view: np.ndarray, error: float, min_step: float) -> Decision | None:
        bound = float(self._lost_bounds[self.index])
        if error <= bound:  # the window holds the current subgoal: its best is no worse
            self._lost_count = 0
            return None
        if error < self._lost_best - min_step:  # a new best at this subgoal: closing in, not lost (yet)
            self._lost_best = error
            return None
        ahead = max(self.cfg.lookahead, LOST_WINDOW)
        window = range(max(0, self.index - 2), min(len(self), self.index + 1 + ahead))
        errors = self.matcher.distances(view, self._feats[window.start : window.stop])
        best = int(np.argmin(errors))
        if errors[best] <= bound:
            self._lost_count = 0
            return None
        self._lost_count += 1
        if self._lost_count < self.cfg.lost_steps:
            return None
        return self._stop(
            Action.LOST,
            error,
            f"lost at subgoal {self.index}, best match error {errors[best]:.3f} (subgoal {window.start + best}) "
            f"above {bound:.3f} for {self.cfg.lost_steps} steps",
        )

    def _localise(self, view: np.ndarray) -> Decision | None:
        errors = self.matcher.distances(view, self._feats)
        best = int(np.argmin(errors))
        floor = self.cfg.localise_max_error if self.cfg.localise_max_error is not None else 3.0 * self.e_m
        if errors[best] > floor:
            return None
        self.localised_to = best
        if best == self.index:
            return None
        self._set_index(best)
        return Decision(Action.JUMP, best, float(errors[best]), note=f"localised to subgoal {best}")

    def _unstall(self, view: np.ndarray, error: float, stop: bool = True) -> Decision | None:
        """JUMP ahead, accept a plateau, or (``stop``) STALLED; with ``stop`` False None when neither."""
        i = self.index
        bound = self.cfg.jump_factor * self.thresholds[i]
        ahead = range(i + 1, min(i + 1 + self.cfg.lookahead, len(self)))
        if len(ahead):
            errors = self.matcher.distances(view, self._feats[ahead.start : ahead.stop])
            best = int(np.argmin(errors))
            if (
                errors[best] <= self.cfg.jump_factor * self.thresholds[ahead.start + best]
                and errors[best] < error
            ):
                self.jumps += 1
                self._set_index(ahead.start + best)
                return Decision(Action.JUMP, self.index, float(errors[best]), note="stall guard")
        moved = True
        if self.cfg.plateau_needs_motion and self._plateau_view is not None:
            gap = self.gaps[i - 1] if i > 0 else (self.gaps[0] if len(self.gaps) else 0.0)
            moved = self.matcher.distance(view, self._plateau_view) >= self.cfg.motion_fraction * gap
        if error <= bound and moved:
            # The policy has brought the robot as close as it can (its output has a small dead zone near
            # the goal): accept the subgoal rather than give up a route the robot is still on.
            self.plateaus += 1
            self._plateau_view = view
            self._set_index(i + 1)
            return Decision(Action.ADVANCE, self.index, error, note="accepted on plateau")
        if not stop:
            return None
        why = (
            "the robot has not moved since the last plateau acceptance"
            if error <= bound
            else (
                f"none of the next {self.cfg.lookahead} subgoals is within {self.cfg.jump_factor} thresholds = {bound:.3f}"
            )
        )
        return self._stop(
            Action.STALLED,
            error,
            f"error {error:.3f} stopped falling for {self.cfg.stall_steps} steps and {why}",
        )
