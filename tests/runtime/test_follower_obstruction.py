"""The follower stops for what is in the way, camera only (runtime.obstruction in runtime.follower)."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest
from floor_fakes import box_at, floor_view, straight_route

from vtr.runtime.contracts import ROBOT_RADIUS, Observation
from vtr.runtime.controller import Action, ControllerConfig
from vtr.runtime.follower import Follower
from vtr.runtime.frame import as_frame
from vtr.runtime.repeater import RepeatConfig, Repeater, RepeatStatus
from vtr.runtime.route import Route
from vtr.runtime.route_sensing import floor_side_of

#: The box's half side (m): the robot touches it with its centre this plus its radius from the box's.
HALF_BOX = 0.125


class FloorRobot:
    """A robot driving along x over the floor of floor_fakes, with a 25 cm box on its path at ``box_x``
    (until ``removed_after`` s); a contact is reported once its body reaches the box."""

    def __init__(self, box_x: float | None, removed_after: float = float("inf")) -> None:
        self.x, self.t, self.box_x, self.removed_after = 0.0, 0.0, box_x, removed_after
        self.touched = False

    def box_there(self) -> bool:
        return self.box_x is not None and self.t < self.removed_after

    def observe(self) -> Observation:
        image = floor_view(self.x)
        if self.box_there():
            assert self.box_x is not None
            image = box_at(image, max(self.box_x - self.x, 0.05))
        return Observation(image, self.t, pose=(self.x, 0.0, 0.0), collided=self.touched)

    def step(self, v: float, w: float, duration: float) -> Observation:
        self.x += v * duration
        if self.box_there() and self.box_x is not None and self.x >= self.box_x - HALF_BOX - ROBOT_RADIUS:
            self.x, self.touched = self.box_x - HALF_BOX - ROBOT_RADIUS, True
        self.t += duration
        return self.observe()

    def stop(self) -> None:
        pass


class Forward:
    """A policy that drives straight on whatever it sees (the network facing a box it cannot match)."""

    image_shape = (128, 128)

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        return np.array([[0.25, 0.25], [0.0, 0.0]], dtype=np.float32)


def floor_route(n: int = 16) -> Route:
    """A straight route of ``n`` subgoals 0.1 m apart over the floor, taught at 0.25 m/s."""
    views, poses = straight_route(n, 0.1)
    commands = np.zeros((n, 2))
    commands[:-1, 0] = 0.25
    return Route(images=views, poses=poses, commands=commands, name="floor", dt=0.1)


def repeat(robot: FloorRobot, route: Route | None = None, wait_s: float = 2.0, **cfg) -> Repeater:
    config = RepeatConfig(controller=ControllerConfig(zero_bias=0.0, **cfg), max_steps=200, wait_s=wait_s)
    rep = Repeater(robot, Forward(), route or floor_route(), config=config)
    rep.run()
    return rep


def test_without_a_box_the_floor_route_finishes():
    robot = FloorRobot(None)
    rep = repeat(robot)
    assert rep.status is RepeatStatus.FINISHED and rep.waited_steps == 0
    assert robot.x == pytest.approx(1.5, abs=0.1)


def test_a_box_on_the_path_stops_the_robot_before_contact_and_ends_blocked_with_the_evidence():
    robot = FloorRobot(box_x=1.2)
    rep = repeat(robot)
    assert not robot.touched
    assert rep.status is RepeatStatus.BLOCKED, (rep.status, rep.detail)
    assert robot.x <= 1.2 - HALF_BOX - ROBOT_RADIUS - 0.1  # stopped at least 10 cm before its body touches
    assert "way ahead blocked near subgoal" in rep.detail and "of the path region unmatched" in rep.detail
    assert "growing for" in rep.detail and "waited" in rep.detail
    assert rep.waited_steps >= 20


def test_the_robot_resumes_when_the_box_is_taken_away_while_it_waits():
    robot = FloorRobot(box_x=1.2, removed_after=4.0)
    rep = repeat(robot, wait_s=10.0)
    assert not robot.touched and rep.waited_steps > 0
    assert rep.status is RepeatStatus.FINISHED, (rep.status, rep.detail)
    assert robot.x == pytest.approx(1.5, abs=0.1)


def test_the_detector_can_be_switched_off_for_ablations_and_a_route_without_poses_has_none():
    robot = FloorRobot(box_x=1.2)
    rep = repeat(robot, obstruction=False)
    assert robot.touched and rep.status is RepeatStatus.COLLIDED
    route = floor_route()
    assert Follower.for_route(route).obstruction is not None
    unknown = replace(route, poses=np.full_like(route.poses, np.nan))
    assert Follower.for_route(unknown).obstruction is None


def test_blocked_is_not_the_end_for_the_follower():
    route = floor_route()
    follower = Follower.for_route(route, ControllerConfig(zero_bias=0.0))
    x, actions = 0.0, []
    for _ in range(60):
        decision = follower.judge(box_at(floor_view(x), 1.2 - x)).decision
        actions.append(decision.action)
        if decision.action is Action.BLOCKED:
            break
        follower.commanded(0.25, 0.0, 0.1)
        x += 0.025
    assert actions[-1] is Action.BLOCKED and follower.status is None


class FastWall:
    """A wall clock that runs a second per reading: a lockstep robot on a heavily loaded machine."""

    def __init__(self) -> None:
        self.now = 0.0

    def monotonic(self) -> float:
        self.now += 1.0
        return self.now

    def __getattr__(self, name: str):
        return getattr(time, name)


def test_the_wait_runs_on_the_robots_clock_and_on_the_wall_clock_only_where_that_is_stuck(monkeypatch):
    import vtr.runtime.repeater as repeater

    monkeypatch.setattr(repeater, "time", FastWall())
    robot = FloorRobot(box_x=1.2)
    rep = repeat(robot, wait_s=2.0)
    assert rep.status is RepeatStatus.BLOCKED and 20 <= rep.waited_steps <= 22  # 2 s of 0.1 s steps

    class Stuck(FloorRobot):  # its stamps never move
        def observe(self) -> Observation:
            return replace(super().observe(), stamp=0.0)

    stuck = Stuck(box_x=1.2)
    rep = repeat(stuck, wait_s=2.0)
    assert rep.status is RepeatStatus.BLOCKED and rep.waited_steps <= 3


@pytest.mark.parametrize("side_gain", [None, 0.0])
def test_the_detector_warps_the_floor_to_where_the_floor_puts_the_robot_beside_the_path(side_gain):
    """The follower hands the detector the floor registration's (dy, psi), with or without the side turn."""
    cfg = None if side_gain is None else ControllerConfig(side_gain=side_gain)
    follower = Follower.for_route(floor_route(), cfg)
    ask = floor_side_of(follower._floor_side, as_frame(floor_view(0.3, 0.08, -0.1)), 3.0)
    assert ask is not None
    found = ask()
    dy, psi = found.dy, found.psi
    assert dy == pytest.approx(0.08, abs=0.01) and psi == pytest.approx(-0.1, abs=0.02)
    assert (
        Follower.for_route(floor_route(), ControllerConfig(obstruction=False, side_gain=0.0))._floor_side
        is None
    )
