"""Follow a taught route from where the route localiser says the robot is: a pure state machine, an image in,
a decision out (the default repeat controller; ``runtime.controller`` keeps the paper's Algorithm 1).

Each image:

1. a reported contact ends the run (COLLIDED);
2. the localiser (``runtime.localiser``) weighs its belief by the view: where along the route the robot
   is (``position``, in subgoal units) and how sure (``confidence``, ``match``);
3. the end: the floor places the robot at the last taught pose (``runtime.arrival``) or, where the floor does
   not tell, the estimate is at the last subgoal (where the end's floor tells no distance, within half a step
   of it: ``FloorArrival.view_may_end``) and the view matches it as well as the teach's neighbouring views
   match each other, and is no nearer than the one before unless the estimate is within half a step of the end
   (``APPROACH_MARGIN``); or, the view closest to it, the policy has stopped driving there: FINISHED; or,
   after 4 and 5, by travel (``EndWatch``: the views cannot see the robot pass the end, nor turn past the end
   of a final turn in place): moved past what the route had left, within the settled bound (net of a changed
   scene's common offset where the view follows the teach's profile) FINISHED, else LOST with the evidence;
4. blocked: the camera sees the way ahead blocked (``runtime.obstruction``: the floor just ahead, warped from
   the taught view to the estimated pose, stops matching in a region that grew while the robot was commanded
   forward): BLOCKED with the evidence, for as long as the detector says so. Not an end: the repeat loop holds
   the robot still, resumes when the way clears, and ends the run ``blocked`` after its wait. Without taught
   poses (or ``Route.travel_poses``) to warp the floor by there is no camera-only stop (the range scan's
   zones still apply); ``ControllerConfig.obstruction`` turns it off (ablations);
5. lost: for ``lost_steps`` images in a row no subgoal near the estimate matches the view (the best distance
   is over the lost bound there: the route's, or ``lost_factor`` times the taught gaps next to the estimate
   where those are wider, ``thresholds.lost_bounds``) and the match is not improving: LOST, with the evidence;
   or the estimate has not progressed for too many images while the view matched no subgoal under its
   threshold, or, matched or not, for twice as many without new ground or while driven further than the taught
   route covers across the window (``runtime.progress_watch``), or driven further beside the taught path than
   ``BESIDE_M`` by its commands since a view or the floor last placed it (``runtime.beside_watch``): LOST, with
   the evidence (a robot that does not get on, crawls on where views differ, drives on blind, stands, rocks,
   spins, or leaves the path);
6. otherwise COMMAND toward the subgoal the paper's horizon puts ahead of the estimate (``lead`` gaps ahead,
   rounded up to a subgoal), with the taught command at the estimated position as feed-forward
   (``Decision.prior``, blended by the repeat loop; faded out over the last control step of taught motion
   before the end, ``RouteLocaliser.left_to_end``) and no translation where the teach turned in place (from
   where the floor places the robot at the turn's pose, where it tells: ``runtime.pivot``; to where the views
   place it past the turn's end, or the floor shows it turned to that end: ``runtime.turn_end``); where the
   teach drove forward, a turn back toward the taught path (``Decision.turn``, added by the repeat loop) from
   the side offset the floor shows (``runtime.side_turn``: a pure pursuit of the path point ``side_lookahead``
   ahead, at most ``SIDE_TURN_MAX``: VelocityNet alone closes a side offset over a few wall distances).

The subgoal steered to changes because the estimate moved (ADVANCE events when it moved past subgoals, a
JUMP back when the views placed the robot behind); never by a timeout, a plateau or a jump on a stall.
The repeat loop reports every command (:meth:`Follower.commanded`), which moves the estimate along.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from vtr.runtime.arrival import FloorArrival
from vtr.runtime.beside_watch import BesideWatch
from vtr.runtime.controller import Controller
from vtr.runtime.controller_config import ControllerConfig
from vtr.runtime.decisions import Action, Decision, Verdict
from vtr.runtime.floor_view import Camera
from vtr.runtime.frame import Frame, as_frame
from vtr.runtime.kinematics import taught_motion
from vtr.runtime.localiser import Estimate, RouteLocaliser
from vtr.runtime.obstruction import FORWARD_SPEED, ObstructionVerdict, SideFn, moving
from vtr.runtime.pivot import PivotArrival
from vtr.runtime.progress_watch import EndWatch, ProgressWatch, taught_translation
from vtr.runtime.route_sensing import (
    FloorSide,
    floor_camera,
    floor_side_of,
    obstruction_detector,
    side_offset,
)
from vtr.runtime.side_offset import SideEstimate
from vtr.runtime.side_turn import SideTurn
from vtr.runtime.thresholds import bound_between, check_subgoals, lost_bounds, route_views
from vtr.runtime.turn_end import TurnEnd

if TYPE_CHECKING:
    from vtr.runtime.route import Route

#: Commands under these (m/s, rad/s) count as the policy standing still at the end of the route.
IDLE_SPEED, IDLE_TURN = 0.01, 0.02
#: A view nearer the last subgoal's than the view before by more than this (the first near the end counts as
#: nearer) is still approaching it, and ends the run only once the estimate leaves half a control step or
#: less: not the first view under the threshold (dev random:950: 37 mm short while views came nearer; 3 mm).
APPROACH_MARGIN = 0.005


class Follower:
    """Decide, image by image, where to steer from the localiser's estimate (see the module docstring)."""

    def __init__(
        self,
        subgoals: np.ndarray,
        cfg: ControllerConfig | None = None,
        commands: np.ndarray | None = None,
        poses: np.ndarray | None = None,
        travel_poses: np.ndarray | None = None,
        steps_per_subgoal: float = 2.0,
        dt: float = 0.1,
        camera: Camera | None = None,
    ) -> None:
        check_subgoals(subgoals)
        self.cfg = cfg or ControllerConfig()
        n = len(subgoals)
        self.subgoals = subgoals
        self.commands = (
            np.zeros((n, 2)) if commands is None else np.asarray(commands, dtype=np.float64).reshape(-1, 2)
        )
        self._held = Controller.turns_in_place(self.commands, poses, n)
        views = route_views(subgoals, self.cfg)
        self.cfg, self.matcher, self._feats, self.gaps = views.cfg, views.matcher, views.feats, views.gaps
        self.fallback, self.thresholds, self.median_gap = views.fallback, views.thresholds, views.median_gap
        self.lost_bound = views.lost_bound
        #: per subgoal: the route's bound, or ``lost_factor`` times the wider gap next to it where more
        self.lost_bounds = lost_bounds(self.gaps, n, self.cfg, self.lost_bound)
        self._steps = float(steps_per_subgoal)
        motion = taught_motion(travel_poses, self.commands, n, dt * steps_per_subgoal)
        self.localiser = RouteLocaliser(
            self._feats, self.matcher, motion, self.median_gap, self.cfg.localiser
        )
        if self.cfg.localise:
            self.localiser.start_at(None)
        sensed = (subgoals, travel_poses, camera)
        self.obstruction = obstruction_detector(*sensed) if self.cfg.obstruction else None
        self.side = side_offset(*sensed) if self.cfg.side_gain > 0 else None
        # the detector warps the taught floor to where the floor puts the robot beside the path, too
        self._floor_side = self.side or (side_offset(*sensed) if self.obstruction else None)
        self.side_turn = SideTurn(self.cfg.side_gain, self.cfg.side_lookahead)  # toward the taught path
        self.obstructed: ObstructionVerdict | None = None  # the detector's verdict on the last view
        self._speed, self._step_m, self._turn = 0.0, 0.0, 0.0  # the last command: m/s, travel (m), turn (rad)
        self._moved = False  # commanded to drive or turn since the last view
        self.index = 0  # the subgoal steered to
        self.status: Action | None = None
        self.estimate: Estimate | None = None
        self.jumps = 0
        self.plateaus = 0  # kept for the summary: this controller never accepts a subgoal on a plateau
        self.localised_to: int | None = None
        self._lost_count, self._lost_best = 0, math.inf
        window = self.cfg.localiser.window_behind + self.cfg.localiser.window_ahead
        #: images and commanded translation since the last evidence of where the robot is (``_stalled``)
        self.progress = ProgressWatch(window * self._steps, taught_translation(motion))
        self.beside_watch = BesideWatch(None if travel_poses is None else motion)  # and beside the path
        self.end = EndWatch(self.localiser.travelled, motion, self._held)  # the end by travel (a turn's too)
        self.arrival = FloorArrival.of(self._floor_side, motion, self._held)  # the end by the floor
        self.pivot = PivotArrival(self._floor_side, motion, self._held)  # a turn in place's start by it
        self.turn_end = TurnEnd(self._floor_side, motion, self._held, self.commands[:, 0] == 0)  # and its end
        self._idle, self._finished, self._approach = 0, False, math.inf  # _approach: the last final_error

    @classmethod
    def for_route(cls, route: Route, cfg: ControllerConfig | None = None) -> Follower:
        """The follower of a taught route (its subgoals, commands, poses and spacing)."""
        steps, camera = float(route.steps_between or 2), floor_camera(route.camera)
        taught = (route.commands, route.poses, route.travel_poses(), steps, float(route.dt), camera)
        return cls(route.images, cfg, *taught)

    def __len__(self) -> int:
        return int(self.subgoals.shape[0])

    @property
    def finished(self) -> bool:
        return self._finished

    @property
    def e_m(self) -> float:
        """The final subgoal's match threshold (what FINISHED needs); kept for logs and summaries."""
        return float(self.thresholds[min(self.index, len(self) - 1)])

    @property
    def subgoal(self) -> np.ndarray:
        return self.subgoals[min(self.index, len(self) - 1)]

    def holds_turn(self, i: int) -> bool:
        return self.cfg.hold_turns and 0 <= i < len(self._held) and bool(self._held[i])

    def commanded(self, v: float, w: float, dt: float) -> None:
        """The repeat loop applied (v, w) for ``dt`` seconds: the estimate moves along the route."""
        self._idle = self._idle + 1 if abs(v) < IDLE_SPEED and abs(w) < IDLE_TURN else 0
        self._speed, self._step_m, self._turn = v, abs(v) * dt, abs(w) * dt
        self._moved = self._moved or moving(v, w)
        self.progress.commanded(v, dt)
        self.beside_watch.commanded(v, w, dt)
        self.pivot.commanded(v, dt)
        self.end.commanded(v, w, dt, self.localiser.predict(v, w, dt))

    def relocalise(self) -> None:
        """Search the whole route on the next image (after a robot restart)."""
        self.localiser.start_at(None)
        self.progress.reset()  # counted from where the views place it now
        self.beside_watch.reset()
        self.end.reset()
        if self.obstruction is not None:
            self.obstruction.reset()
        self.pivot.reset()

    def judge(self, image: Frame | np.ndarray, collided: bool = False) -> Verdict:
        """The decision on ``image`` (a frame; an array is checked here, once), with the subgoal changes it
        implies as events."""
        from_index = self.index
        decision = self._decide(as_frame(image, self.subgoals.shape[1:3]), collided)
        events: list[Decision] = []
        if decision.action is Action.COMMAND or decision.action is Action.FINISHED:
            to = len(self) if decision.action is Action.FINISHED else decision.index
            if to > from_index:
                events = [Decision(Action.ADVANCE, k + 1, decision.error) for k in range(from_index, to)]
            elif to < from_index:
                self.jumps += 1
                events = [Decision(Action.JUMP, to, decision.error, note="the view places the robot behind")]
            self.index = to
        return Verdict(decision, tuple(events), from_index)

    def _stop(self, action: Action, error: float, note: str) -> Decision:
        self.status = action
        return Decision(action, self.index, error, note=note)

    def _decide(self, image: Frame, collided: bool) -> Decision:
        if self._finished:
            return Decision(Action.FINISHED, len(self), math.nan)
        if self.status is not None:
            return Decision(self.status, self.index, math.nan, note=f"{self.status.value} earlier")
        if collided and self.cfg.stop_on_contact:
            return self._stop(Action.COLLIDED, math.nan, f"contact reported near subgoal {self.index}")
        wide = self.localiser.wide
        est = self.estimate = self.localiser.update(image)
        if wide:
            self.localised_to = int(round(est.position))
        last = len(self) - 1
        final_error = est.error_to(last)
        at_end = est.position >= last - self.cfg.finish_span and est.best == last  # the end by travel's too
        k = self.cfg.localiser.cells_per_gap  # the estimate's cell (the filter resolves no finer) at the end
        near_end = round(est.position * k) >= round((last - self.cfg.finish_span) * k)
        # FINISHED on evidence: the floor at the last pose, else the view under the last subgoal's threshold at
        # the end; or the last subgoal the closest view, the policy stopped there and the view close to it
        threshold = float(self.thresholds[last])
        close = final_error <= self.cfg.jump_factor * threshold  # the settled bound, the end by travel's too
        floor = None if self.arrival is None else self.arrival.judge(image, est.position, self._step_m)
        by_view = near_end and final_error <= threshold  # asked of the arrival only then (every step is not)
        by_view = by_view and (self.arrival is None or self.arrival.view_may_end(est.position, self._step_m))
        approaching = final_error < self._approach - APPROACH_MARGIN  # a view still coming nearer ends it
        self._approach = final_error if near_end else math.inf  # only once the estimate is within half a step
        by_view = by_view and not (approaching and self.localiser.left_to_end(self._steps) > 0.5)
        arrived, note = floor or (by_view, "")
        if arrived or at_end and self._idle >= 2 and close:  # the evidence in the note (the run's summary)
            self._finished = True
            note = note or f"the view {final_error:.3f} from the last subgoal's (threshold {threshold:.3f})"
            return Decision(Action.FINISHED, len(self), final_error, note=note)
        floor_side = floor_side_of(self._floor_side, image, est.position)  # one registration a view, lazily
        if (blocked := self._blocked(image, est, floor_side)) is not None:
            return blocked
        matched = est.best_error <= float(self.thresholds[est.best])  # a view under its subgoal's threshold
        self.beside_watch.view(est.position, matched, self.side_turn.beside)  # the floor's: the last view's
        if (lost := self._lost(est) or self._stalled(est, matched)) is not None:
            return lost
        if (past := self._past_end(est, at_end, matched, close, final_error)) is not None:
            return past
        gap = min(int(est.position), last - 1) if last > 0 else 0
        # in a taught turn in place: the turn's pose, where the floor places the robot short of it (the belief
        # weighed by that): drive on into it as the teach did (runtime.pivot)
        pose = (
            self.pivot.place(image, gap, self._step_m, self.localiser) if self.holds_turn(gap + 1) else None
        )
        if pose is not None:
            est = self.estimate = self.localiser.last or est
            gap = min(gap, pose - 1)
        elif self.holds_turn(gap + 1) and (end := self.turn_end.witness(image, est.position, self._turn)):
            est = self.estimate = self.localiser.at_least(end)
            gap = end
        target = min(last, int(math.floor(est.position + self.cfg.lead)) + 1, pose or last)
        hold = self.holds_turn(gap + 1)  # the teach turned on the spot where the robot is
        # a taught turn in place is replayed as taught: the policy alone, aiming at the view after it, eased off
        # short of where the views place the robot past it (a plain room; a held-out route's start)
        turn = 1.0 if hold else self.cfg.feed_forward_turn
        # the taught motion left to the end, in control steps: the last of it is VelocityNet's alone (the taught
        # command into the last subgoal, replayed at the end, drove the robot past it)
        left = self.localiser.left_to_end(self._steps)
        prior = None
        if (self.cfg.feed_forward > 0 or turn > 0) and last > 0:
            prior = (left * self.cfg.feed_forward, left * turn, *map(float, self.commands[gap]))
        return Decision(
            Action.COMMAND,
            target,
            est.error_to(target),
            then_stop=not self.cfg.continuous,
            note=f"at {est.position:.2f} (confidence {est.confidence:.2f})",
            v_limit=0.0 if hold else math.inf,
            prior=prior,
            turn=self._side_turn(floor_side, gap, driving=not hold and last > 0),
        )

    @property
    def beside(self) -> SideEstimate | None:
        """Where the floor put the robot beside the taught path on the last command (None: it did not tell)."""
        return self.side_turn.beside

    def _side_turn(self, floor_side: FloorSide | None, gap: int, driving: bool) -> float:
        """The turn (rad/s) toward the taught path that the floor's side offset asks for (``runtime.side_turn``);
        none where the teach or the robot did not drive forward (turning closes no side offset on the spot) or
        the floor does not tell (``runtime.side_offset``)."""
        speed = min(float(self.commands[gap, 0]), self._speed)  # the pace the robot is driving at
        if driving and self.side is not None and floor_side is not None and speed > FORWARD_SPEED:
            return self.side_turn.turn(floor_side())
        return self.side_turn.turn(None)

    def _blocked(self, image: Frame, est: Estimate, floor_side: FloorSide | None) -> Decision | None:
        """BLOCKED while the obstruction detector sees the way ahead blocked (None: go on)."""
        if self.obstruction is None:
            return None
        moved, self._moved = self._moved, False
        side: SideFn | None = None if floor_side is None else lambda: _floor_pose(floor_side())
        verdict = self.obstructed = self.obstruction.update(image, est.position, moved, side)
        if not verdict.blocked:
            return None
        # what spoils the match is in the way, not elsewhere; and a robot held still makes no progress
        self._lost_count, self._lost_best = 0, math.inf
        self.progress.reset()
        return Decision(
            Action.BLOCKED,
            self.index,
            est.error_to(min(self.index, len(self) - 1)),
            note=f"way ahead blocked near subgoal {int(round(est.position))}: {verdict.fraction:.0%} of the "
            f"path region unmatched ({verdict.hidden:.0%} up to its far end), growing for "
            f"{verdict.growing_steps} steps",
        )

    def _lost(self, est: Estimate) -> Decision | None:
        bound = bound_between(self.lost_bounds, est.position)
        if self.cfg.lost_steps <= 0 or est.best_error <= bound:
            self._lost_count, self._lost_best = 0, math.inf
            return None
        if est.best_error < self._lost_best - 0.02 * bound:  # still closing in on a match
            self._lost_best = est.best_error
            return None
        self._lost_count += 1
        if self._lost_count < self.cfg.lost_steps:
            return None
        return self._stop(
            Action.LOST,
            est.best_error,
            f"lost near subgoal {int(round(est.position))}: best match {est.best_error:.3f} at subgoal "
            f"{est.best} (bound {bound:.3f}), confidence {est.confidence:.2f}",
        )

    def _past_end(
        self, est: Estimate, at_end: bool, matched: bool, close: bool, error: float
    ) -> Decision | None:
        """The end by travel (``EndWatch``): FINISHED where the view matches the last subgoal within the settled
        bound (``close``), or does net of a changed scene's common offset (``est.match``) where its distances follow
        the teach's profile (``est.fit``), else LOST with the evidence; None while the robot has route left."""
        fits = est.fit <= 1.0  # no noisier about the profile than the localiser expects: changed alike
        net = fits and est.best_error - est.match <= float(self.thresholds[est.best])
        if (spent := self.end.judge(est.position, at_end, matched or net)) is None:
            return None
        last = len(self) - 1
        threshold = float(self.thresholds[last])
        if close or fits and error - est.match <= self.cfg.jump_factor * threshold:
            self._finished = True
            return Decision(Action.FINISHED, len(self), error, note=f"at the route's end: {spent}")
        return self._stop(
            Action.LOST,
            error,
            f"lost at the route's end: {spent}, the view {error:.3f} from subgoal {last}'s (threshold "
            f"{threshold:.3f}), best match {est.best_error:.3f} at subgoal {est.best}",
        )

    def _stalled(self, est: Estimate, matched: bool) -> Decision | None:
        """LOST when the estimate has made no progress for too long, views matching or not (the counts are
        ``runtime.progress_watch``'s). ``lost_steps`` <= 0 (no lost verdict at all) turns it off."""
        if self.cfg.lost_steps <= 0:
            return None
        window_m = self.localiser.window_travel(est.position)
        spent = self.progress.judge(est.position, matched, window_m) or self.beside_watch.judge()
        if spent is None:
            return None
        return self._stop(
            Action.LOST,
            est.best_error,
            f"lost near subgoal {int(round(est.position))}: {spent}, best match {est.best_error:.3f} at "
            f"subgoal {est.best} (threshold {float(self.thresholds[est.best]):.3f}), confidence "
            f"{est.confidence:.2f}",
        )


def _floor_pose(found: SideEstimate | None) -> tuple[float, float, float] | None:
    return None if found is None else (found.dy, found.psi, found.dx)


#: Either controller: the route localiser's (default) or the threshold rules' (``switching="rules"``).
RouteController = Controller | Follower


def controller_for_route(route: Route, cfg: ControllerConfig | None = None) -> RouteController:
    """The controller ``cfg.switching`` names, built for ``route``."""
    cfg = cfg or ControllerConfig()
    return (
        Follower.for_route(route, cfg) if cfg.switching == "localiser" else Controller.for_route(route, cfg)
    )


__all__ = ["Follower", "RouteController", "controller_for_route"]
