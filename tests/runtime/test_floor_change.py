"""runtime.floor_change: a floor that changed since the teach is kept out of VelocityNet's view where the teach
drove straight on; the repeat loop shows the policy that view."""

from __future__ import annotations

import math

import numpy as np
from floor_fakes import CAM, floor_view, straight_route

from vtr.runtime.contracts import Observation
from vtr.runtime.controller import ControllerConfig
from vtr.runtime.floor_change import FloorChange
from vtr.runtime.frame import as_frame
from vtr.runtime.repeater import RepeatConfig, Repeater
from vtr.runtime.route import Route
from vtr.runtime.side_offset import SideOffset

N = 8


def change(straight: bool = True) -> tuple[FloorChange, np.ndarray, SideOffset]:
    views, poses = straight_route(N, 0.1)
    registration = SideOffset(views, poses, CAM)
    return FloorChange(registration, np.full(N, straight)), views, registration


def test_a_relaid_floor_is_shown_as_the_subgoals_below_the_registered_rows_and_the_camera_above():
    floor, views, registration = change()
    camera = floor_view(0.21, seed=5)  # the same poses, every square laid again in other colours
    assert registration.floor_match(camera, 2.1) > registration.cfg.match
    shown = floor.shown(as_frame(camera), 2.1, views[3])
    row = registration.floor_row
    assert floor.changed and shown is not None and 64 < row < 128
    assert np.array_equal(shown.image[:row], camera[:row]) and np.array_equal(
        shown.image[row:], views[3][row:]
    )


def test_the_taught_floor_is_shown_as_the_camera_sees_it():
    floor, views, registration = change()
    camera = floor_view(0.21, 0.02)  # 2 cm beside the path over the taught floor
    assert registration.floor_match(camera, 2.1) < registration.cfg.match
    assert floor.shown(as_frame(camera), 2.1, views[3]) is None and not floor.changed


def test_where_the_teach_turned_or_nothing_registers_the_floor_the_camera_is_shown():
    floor, views, _ = change(straight=False)
    relaid = as_frame(floor_view(0.21, seed=5))
    assert floor.shown(relaid, 2.1, views[3]) is None and not floor.changed
    assert FloorChange(None, np.ones(N, bool)).shown(relaid, 2.1, views[3]) is None


class RelaidRobot:
    """A unicycle driving along x over the floor of floor_fakes laid with ``seed`` (0: the taught floor)."""

    def __init__(self, seed: int) -> None:
        self.x, self.t, self.seed = 0.0, 0.0, seed
        self.seen: list[np.ndarray] = []

    def observe(self) -> Observation:
        image = floor_view(self.x, seed=self.seed)
        self.seen.append(image)
        return Observation(image, self.t, pose=(self.x, 0.0, 0.0))

    def step(self, v: float, w: float, duration: float) -> Observation:
        self.x += v * duration
        self.t += duration
        return self.observe()

    def stop(self) -> None:
        pass


class Recording:
    """A policy that drives on at 0.25 m/s and keeps the views it was shown with their subgoals."""

    image_shape = (128, 128)

    def __init__(self) -> None:
        self.pairs: list[tuple[np.ndarray, np.ndarray]] = []

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        self.pairs.append((np.asarray(current), np.asarray(subgoal)))
        return np.array([[0.25, 0.25], [0.0, 0.0]], dtype=np.float32)


def repeat_over(seed: int) -> tuple[RelaidRobot, Recording, int]:
    views, poses = straight_route(N, 0.1)
    commands = np.zeros((N, 2))
    commands[:-1, 0] = 0.25
    route = Route(images=views, poses=poses, commands=commands, name="relaid", dt=0.1)
    robot, policy = RelaidRobot(seed), Recording()
    cfg = RepeatConfig(
        controller=ControllerConfig(zero_bias=0.0, obstruction=False, continuous=True), max_steps=6
    )
    rep = Repeater(robot, policy, route, config=cfg)
    for _ in range(6):
        rep.step()
    return robot, policy, SideOffset(views, poses, CAM).floor_row


def test_the_repeat_shows_the_policy_the_subgoals_floor_on_a_relaid_floor_and_the_camera_on_the_taught_one():
    robot, policy, row = repeat_over(seed=5)
    assert len(policy.pairs) >= 4
    for (shown, subgoal), camera in zip(policy.pairs, robot.seen[: len(policy.pairs)], strict=True):
        assert np.array_equal(shown[:row], camera[:row]) and np.array_equal(shown[row:], subgoal[row:])
        assert not np.array_equal(shown[row:], camera[row:])
    robot, policy, _ = repeat_over(seed=0)
    assert len(policy.pairs) >= 4
    assert all(
        np.array_equal(shown, camera)
        for (shown, _), camera in zip(policy.pairs, robot.seen[: len(policy.pairs)], strict=True)
    )
    assert math.isfinite(row)
