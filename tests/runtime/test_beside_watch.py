"""runtime.beside_watch: the robot's offset from the taught path, dead-reckoned from its commands since a view or
the floor last placed it there (held-out set 46: two 10 cm starts turned past the path, matched nothing and drove
on with the estimate carried along the route until they touched furniture)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from runtime_fakes import render

from vtr.runtime.beside_watch import BESIDE_M, BesideWatch
from vtr.runtime.controller import Action, ControllerConfig
from vtr.runtime.follower import Follower
from vtr.runtime.route import Route
from vtr.runtime.side_offset import SideEstimate

GAP = 0.05  # m a gap


def straight(n: int = 60) -> BesideWatch:
    return BesideWatch(np.tile([GAP, 0.0], (n - 1, 1)))


def drive(watch: BesideWatch, v: float, w: float, steps: int, position: float = 5.0, dt: float = 0.1) -> list:
    """``steps`` commands of (v, w), each after an unmatched view at ``position`` that the floor did not tell:
    the verdicts, the last one's after the last command."""
    notes = []
    for _ in range(steps):
        watch.view(position, matched=False, floor=None)
        notes.append(watch.judge())
        watch.commanded(v, w, dt)
    notes.append(watch.judge())
    return notes


def test_driving_on_the_taught_heading_without_evidence_stays_on_the_path():
    watch = straight()
    assert drive(watch, 0.3, 0.0, 200) == [None] * 201
    assert watch.beside == 0.0 and watch.since == pytest.approx(6.0)


def test_driving_turned_off_the_path_without_evidence_is_caught_past_the_bound():
    """The floor placed the robot on the path turned 30 deg to the right; then nothing told: after d metres it
    is d sin 30 deg to the right, and past BESIDE_M the watch says so, with the metres driven."""
    watch = straight()
    watch.view(5.0, matched=False, floor=SideEstimate(dy=0.0, psi=-math.radians(30), rows=10))
    notes = drive(watch, 0.3, 0.0, 40)
    first = next(k for k, note in enumerate(notes) if note is not None)
    driven = 0.03 * first
    assert driven * 0.5 > BESIDE_M >= (driven - 0.03) * 0.5  # caught on the first view past the bound
    assert f"driven {driven:.2f} m" in notes[first] and "to the right of the taught path" in notes[first]


def test_a_matching_view_puts_the_robot_back_on_the_path():
    watch = straight()
    watch.view(5.0, matched=False, floor=SideEstimate(dy=0.0, psi=math.radians(30), rows=10))
    drive(watch, 0.25, 0.0, 12)  # 0.3 m at 30 deg: 0.15 m to the left
    assert watch.beside == pytest.approx(0.15) and watch.judge() is None
    watch.view(6.0, matched=True, floor=None)
    assert (watch.beside, watch.relative, watch.since) == (0.0, 0.0, 0.0)
    assert drive(watch, 0.25, 0.0, 40, position=6.0) == [None] * 41  # on the taught heading again


def test_the_floor_sets_the_heading_and_the_offset_counts_from_where_it_placed_the_robot():
    """The offset the floor reads is the side turn's to close; what the watch bounds is the drive since the
    evidence (one reading can be centimetres off: dev house random:955 read -219 mm where the robot was 12 mm
    to the left)."""
    watch = straight()
    watch.view(5.0, matched=False, floor=SideEstimate(dy=0.08, psi=0.1, rows=10))
    assert watch.beside == 0.0 and watch.relative == pytest.approx(0.1)
    watch.commanded(0.2, -1.0, 0.1)  # the turn counts from the next view on
    assert watch.beside == pytest.approx(0.02 * math.sin(0.1))
    watch.view(5.0, matched=False, floor=None)
    assert watch.relative == pytest.approx(0.0)


def test_in_a_taught_arc_a_robot_turning_with_it_stays_on_the_path():
    """The taught heading at the estimate is the teach's: a robot that turns as the teach turned, with the
    estimate moving as it did, is on the path; one that drives straight on leaves it."""
    turn = 0.05  # rad a gap
    motion = np.tile([GAP, turn], (80, 1))
    follows, straight_on = BesideWatch(motion), BesideWatch(motion)
    for k in range(60):  # a gap a step
        for watch in (follows, straight_on):
            watch.view(float(k), matched=False, floor=None)
        follows.commanded(GAP / 0.1, turn / 0.1, 0.1)
        straight_on.commanded(GAP / 0.1, 0.0, 0.1)
    assert abs(follows.beside) < 1e-9 and follows.judge() is None
    assert straight_on.beside < -BESIDE_M and "to the right of" in straight_on.judge()


def test_turning_in_place_moves_nothing_beside_the_path():
    watch = straight()
    assert drive(watch, 0.0, 1.0, 100) == [None] * 101
    assert watch.beside == 0.0 and watch.since == 0.0


def test_before_the_first_view_commands_count_nothing_and_reset_forgets():
    watch = straight()
    watch.commanded(0.3, 1.0, 1.0)
    assert watch.heading is None and watch.beside == 0.0
    watch.view(5.0, matched=False, floor=SideEstimate(dy=0.1, psi=0.5, rows=10))
    watch.reset()
    assert watch.heading is None and watch.beside == 0.0 and watch.since == 0.0


def test_the_taught_heading_is_interpolated_between_subgoals_and_held_past_the_ends():
    watch = BesideWatch(np.array([[GAP, 0.2], [0.0, 0.4]]))
    assert [watch.taught_heading(p) for p in (-1.0, 0.0, 0.5, 1.0, 1.5, 2.0, 9.0)] == pytest.approx(
        [0.0, 0.0, 0.1, 0.2, 0.4, 0.6, 0.6]
    )
    assert BesideWatch(np.zeros((0, 2))).taught_heading(3.0) == 0.0


def test_a_route_without_a_taught_path_has_no_watch():
    watch = BesideWatch(None)
    watch.view(5.0, matched=False, floor=SideEstimate(dy=0.0, psi=1.0, rows=10))
    assert drive(watch, 0.3, 0.0, 100) == [None] * 101 and watch.heading is None


def _corridor_drive(w: float) -> tuple[list[Action], str]:
    """4 m of straight corridor taught at 0.25 m/s; the robot is commanded (0.25 m/s, ``w``) and every view is
    noisy enough to match no subgoal (as ``test_follower_end``'s robot that keeps progressing with a poor
    match): the follower's decisions until it stops commanding, or 3.8 m, and the last one's note."""
    xs = np.arange(0.0, 4.0 + 1e-9, 0.05)
    poses = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], axis=1)
    commands = np.zeros((len(xs), 2))
    commands[:-1, 0] = 0.25
    route = Route(
        images=np.stack([render(x / 4) for x in xs]), poses=poses, commands=commands, name="c", dt=0.1
    )
    follower = Follower.for_route(route, ControllerConfig(zero_bias=0.0))
    rng = np.random.default_rng(0)
    x, actions, note = 0.0, [], ""
    while x < 3.8 and (not actions or actions[-1] is Action.COMMAND):
        noisy = render(x / 4).astype(np.float64) + rng.normal(0.0, 3.0, route.images.shape[1:])
        decision = follower.judge(np.clip(noisy, 0, 255).astype(np.uint8)).decision
        actions.append(decision.action)
        note = decision.note
        follower.commanded(0.25, w, 0.1)
        x += 0.025
    return actions, note


def test_the_follower_ends_a_drive_away_from_the_path_without_evidence_lost_with_it():
    """The same drive on the taught heading goes on (``test_follower_end``); turning 0.3 rad/s off it with
    nothing matching, the estimate still moves along the route, and the run ends LOST once the commands have
    taken the robot BESIDE_M beside the path: after the arc whose sagitta that is."""
    straight_on, _ = _corridor_drive(0.0)
    assert set(straight_on) == {Action.COMMAND}
    actions, note = _corridor_drive(0.3)
    assert actions[-1] is Action.LOST and set(actions[:-1]) == {Action.COMMAND}
    # the offset the commands made before view m: 0.025 m a step at the heading of the view before each
    beside = np.cumsum(0.025 * np.sin(0.03 * np.arange(200)))
    assert len(actions) - 1 == int(np.argmax(beside > BESIDE_M)) + 1  # the first view past the bound
    assert note.startswith("lost near subgoal") and "m further to the left of the taught path" in note
