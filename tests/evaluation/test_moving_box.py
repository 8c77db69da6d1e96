"""The moving obstacle of the condition suite: a box that crosses the taught path ahead of the robot."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from vtr.evaluation.condition_run import CONDITIONS
from vtr.evaluation.conditions import MOVING_SCENES, write_scene_house
from vtr.evaluation.moving_box import SPEED, TRIGGER_M, CrossingRobot
from vtr.evaluation.path_boxes import PATH_BOX_SIDE, box_of
from vtr.sim2d import SimConfig, Simulator
from vtr.sim2d.local_robot import LocalRobot

#: 1.6 m east along y = 3.0 in the living room.
PATH = np.array([[2.0 + 0.05 * k, 3.0, 0.0] for k in range(33)])


@pytest.fixture(scope="module")
def crossing_house(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, dict]:
    house = write_scene_house("moving_obstacle", tmp_path_factory.mktemp("h"), path=PATH)
    return str(house), json.loads(house.read_text())


def test_the_box_waits_beside_the_path_half_way_along(crossing_house):
    _, data = crossing_house
    box = box_of(data)
    assert box is not None and box["size"] == [PATH_BOX_SIDE] * 2
    assert box["crossing"] == pytest.approx([2.8, 3.0]) and box["center"] == pytest.approx([2.8, 3.8])
    assert box["sweep_to"] == pytest.approx([2.8, 2.2])
    cond = CONDITIONS["moving_obstacle"]
    assert cond.scene in MOVING_SCENES and cond.expect == "finished"


def robot_at(house: str, x: float, y: float) -> CrossingRobot:
    box = box_of(json.loads(Path(house).read_text(encoding="utf-8")))
    robot = CrossingRobot(LocalRobot(Simulator(SimConfig(house=house))), box or {})
    robot.reset(pose=(x, y, 0.0))
    return robot


def test_it_crosses_once_the_robot_is_near_and_ends_as_far_on_the_other_side(crossing_house):
    house, _ = crossing_house
    far = robot_at(house, 2.8 - TRIGGER_M - 0.1, 3.0)  # not near enough: it stays
    for _ in range(5):
        far.step(0.0, 0.0, 0.1)
    assert far.started_at is None and far.travelled == 0.0
    robot = robot_at(house, 2.0, 3.0)
    before = robot.observe().image
    images = [robot.step(0.0, 0.0, 0.1).image for _ in range(round(1.6 / SPEED / 0.1) + 5)]
    assert robot.started_at == 0.0 and robot.travelled == pytest.approx(1.6)
    assert robot.robot.sim.house.furniture[-1].center == pytest.approx((2.8, 2.2))
    assert any(not np.array_equal(before, image) for image in images)
    assert robot.closest == pytest.approx(2.8 - PATH_BOX_SIDE / 2 - 2.0, abs=0.01)  # as it passed ahead


def test_it_waits_rather_than_run_into_the_robot(crossing_house):
    house, _ = crossing_house
    robot = robot_at(house, 2.8, 3.0)  # standing on the crossing
    for _ in range(40):
        robot.step(0.0, 0.0, 0.1)
    assert not robot.robot.sim.collided
    assert robot.robot.sim.house.furniture[-1].center[1] >= 3.0 + 0.17 + PATH_BOX_SIDE / 2 - 1e-9
