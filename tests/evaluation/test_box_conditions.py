"""The box conditions of the condition suite: a box on the taught path, and the same box taken away while
the robot waits; what "completed" means for each."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from vtr.evaluation.condition_run import CONDITIONS, judged
from vtr.evaluation.conditions import write_scene_house
from vtr.evaluation.path_boxes import (
    PATH_BOX_SIDE,
    ClearingRobot,
    box_distance,
    box_of,
    path_box,
    write_cleared_house,
)


def l_path() -> np.ndarray:
    """1 m east along y = 3.0 in the living room, a turn in place, then 0.6 m north."""
    east = [[2.2 + 0.05 * k, 3.0, 0.0] for k in range(21)]
    turn = [[3.2, 3.0, math.pi / 4], [3.2, 3.0, math.pi / 2]]
    north = [[3.2, 3.0 + 0.05 * k, math.pi / 2] for k in range(1, 13)]
    return np.array(east + turn + north)


def test_the_box_lands_on_the_taught_path_half_way_along_and_is_not_refused(tmp_path):
    from vtr.sim2d import load_house

    path = l_path()
    house_path = write_scene_house("box_on_path", tmp_path, path=path)  # blocks the path: no PathBlocked
    data = json.loads(house_path.read_text())
    box = box_of(data)
    assert box is not None and box["size"] == [PATH_BOX_SIDE] * 2
    # 1.6 m of path: the box's centre 0.8 m along the first leg, square to it
    assert box["center"] == pytest.approx([3.0, 3.0]) and box["angle_deg"] == pytest.approx(0.0)
    assert load_house(house_path).clearance(2.6, 3.0) == pytest.approx(3.0 - PATH_BOX_SIDE / 2 - 2.6)
    assert all(math.hypot(p["x"] - 3.0, p["y"] - 3.0) > 0.4 for p in data["start_poses"])
    with pytest.raises(ValueError, match="needs a taught path"):
        write_scene_house("box_on_path", tmp_path, path=path[:1])


def test_box_distance_is_to_the_nearest_face_and_the_box_can_be_taken_away(tmp_path):
    box = {"center": [1.0, 1.0], "size": [0.2, 0.4], "angle_deg": 90.0}  # 0.4 m along x once turned
    assert box_distance(box, 1.5, 1.0) == pytest.approx(0.3)
    assert box_distance(box, 1.0, 1.4) == pytest.approx(0.3)
    assert box_distance(box, 1.3, 1.2) == pytest.approx(math.hypot(0.1, 0.1))
    assert box_distance(box, 1.05, 1.0) == 0.0
    house = write_scene_house("box_on_path", tmp_path, path=l_path())
    assert path_box(str(house)) is not None and path_box("house") is None
    cleared = write_cleared_house(str(house))
    assert path_box(str(cleared)) is None
    assert (
        len(json.loads(cleared.read_text())["furniture"])
        == len(json.loads(house.read_text())["furniture"]) - 1
    )


@pytest.mark.parametrize(
    ("expect", "outcome", "touched", "beside", "completed", "cause"),
    [
        ("finished", "finished", False, "", True, ""),
        ("finished", "finished", True, "", False, "finished but touched furniture"),
        ("finished", "finished", False, "mean 40 mm", False, "finished off the route: mean 40 mm"),
        ("finished", "blocked", False, "", False, "blocked: in the way"),
        ("blocked", "blocked", False, "", True, ""),
        ("blocked", "blocked", True, "", False, "blocked after a contact"),
        ("blocked", "collided", True, "", False, "collided: in the way"),
        ("blocked", "finished", False, "", False, "finished past the box"),
        ("blocked", "stalled", False, "", False, "stalled: in the way"),
    ],
)
def test_completed_means_did_what_the_condition_expects(expect, outcome, touched, beside, completed, cause):
    assert judged(expect, outcome, "in the way", touched, beside) == (completed, cause)


def test_the_box_conditions_say_what_they_expect():
    assert CONDITIONS["box_on_path"].expect == "blocked" and CONDITIONS["box_on_path"].clear_after_s is None
    removed = CONDITIONS["box_removed"]
    assert removed.scene == "box_on_path" and removed.expect == "finished" and removed.clear_after_s == 2.0
    others = [c for name, c in CONDITIONS.items() if not name.startswith("box_")]
    assert others and all(c.expect == "finished" and c.clear_after_s is None for c in others)
    with pytest.raises(ValueError, match="expect"):
        type(removed)(expect="stopped")


class FakeSim:
    def __init__(self) -> None:
        self.time, self.house = 0.0, "boxed"

    def set_house(self, house: str) -> None:
        self.house = house


class Driven:
    """A robot whose simulator's clock moves with every step."""

    def __init__(self) -> None:
        self.sim, self.last = FakeSim(), None

    def reset(self, pose=None, seed=None):
        return "obs"

    def observe(self):
        return "obs"

    def step(self, v, w, duration):
        self.sim.time += duration
        return "obs"

    def stop(self) -> None:
        pass


def test_the_box_is_taken_away_once_the_robot_has_stood_long_enough():
    robot = ClearingRobot(Driven(), "cleared", after_s=2.0, dt=0.1)
    robot.reset()
    for _ in range(30):  # driving: never
        robot.step(0.2, 0.0, 0.1)
    for _ in range(15):  # 1.5 s standing, then it moves again: the count starts over
        robot.step(0.0, 0.0, 0.1)
    robot.step(0.1, 0.0, 0.1)
    for _ in range(10):  # 1 s of zero steps and 1 s of polled views
        robot.step(0.0, 0.0, 0.1)
        assert robot.robot.sim.house == "boxed"
    for _ in range(10):
        robot.observe()
    assert robot.robot.sim.house == "cleared" and robot.cleared_at == pytest.approx(5.6)


@pytest.fixture(scope="module")
def small_model(tmp_path_factory: pytest.TempPathFactory):
    from vtr.benchmarks.standin import make_standin_velocitynet
    from vtr.runtime.model_meta import ModelMeta

    meta = ModelMeta(image_height=32, image_width=32)
    return make_standin_velocitynet(tmp_path_factory.mktemp("m") / "tiny.onnx", meta=meta, widths=(8, 16, 16))


def test_the_suite_runs_the_box_conditions_and_says_where_the_robot_ended(small_model, tmp_path):
    from vtr.evaluation import condition_suite as suite

    cfg = suite.SuiteConfig(
        model=small_model,
        routes=("ho_study_arc",),
        conditions=("box_removed",),
        seeds=(0,),
        controllers=("after",),
        models=("fp32",),
        workers=1,
        max_steps_factor=0.25,
        json_path=tmp_path / "suite.json",
    )
    result = suite.run(cfg)
    (run,) = result["runs"]  # the box stands on the path: never refused as path_blocked
    assert run["ran"] and run["box_face_m"] >= 0.0 and "cleared_at_s" in run
    assert run["completed"] == (run["status"] == "finished" and run["cause"] == "")
    (row,) = result["table"]
    assert row["box_face_m"] == pytest.approx(run["box_face_m"])
    assert f"(ended {run['box_face_m']:.2f} m from the box)" in (tmp_path / "suite.md").read_text()


def test_the_box_beside_the_path_stands_clear_of_the_robot_on_it(tmp_path):
    from vtr.evaluation.conditions import ROBOT_RADIUS, path_clearance
    from vtr.evaluation.path_boxes import BESIDE_OFFSET

    path = l_path()
    data = json.loads(write_scene_house("box_beside_path", tmp_path, path=path).read_text())
    box = box_of(data)
    assert box is not None and box["size"] == [PATH_BOX_SIDE] * 2
    # half-way along (0.8 m along the first leg), square to it, to its right: on the left the second leg
    # (north along x = 3.2) would pass 0.2 m from the box's centre
    assert box["center"] == pytest.approx([3.0, 3.0 - BESIDE_OFFSET]) and box["angle_deg"] == pytest.approx(
        0.0
    )
    near = min(box_distance(box, x, y) for x, y, _ in path)
    assert near == pytest.approx(BESIDE_OFFSET - PATH_BOX_SIDE / 2)
    gap, _ = path_clearance(data, path)
    assert gap >= ROBOT_RADIUS + 0.1 - 1e-6
    assert CONDITIONS["box_beside_path"].expect == "finished"


def test_the_stop_table_counts_how_runs_ended():
    from vtr.evaluation.condition_tables import stops

    base = {"controller": "after", "model": "fp32", "ran": True, "contacts": 0, "on_route": True}
    runs = [
        {**base, "condition": "box_on_path", "status": "blocked", "completed": True, "box_face_m": 0.4},
        {**base, "condition": "box_on_path", "status": "blocked", "completed": True, "box_face_m": 0.5},
        {**base, "condition": "box_on_path", "status": "collided", "completed": False, "contacts": 1},
        {**base, "condition": "noise_0.05", "status": "finished", "completed": True},
        {**base, "condition": "noise_0.05", "status": "finished", "completed": False, "on_route": False},
        {**base, "condition": "noise_0.05", "ran": False, "status": "path_blocked"},
    ]
    table = stops([{"runs": runs}])
    assert "| after | fp32 | box_on_path | 3 | 0 | 2 | 1 | 2 | 0.40 / 0.45 | - |" in table
    assert "| after | fp32 | noise_0.05 | 2 | 1 | 0 | 0 | 1 | - | - |" in table


def test_the_box_after_a_turn_stands_half_a_metre_past_the_taught_turn_in_place(tmp_path):
    from vtr.evaluation.path_boxes import turn_ends

    path = np.vstack([l_path(), [[3.2, 3.6 + 0.05 * k, math.pi / 2] for k in range(1, 5)]])  # 0.8 m north
    assert turn_ends(path) == [22]  # the last pose of the turn on the spot
    box = box_of(json.loads(write_scene_house("box_after_turn", tmp_path, path=path).read_text()))
    assert (
        box is not None
        and box["center"] == pytest.approx([3.2, 3.5])
        and box["angle_deg"] == pytest.approx(90)
    )
    assert CONDITIONS["box_after_turn"].expect == "blocked"
    with pytest.raises(ValueError, match="no taught turn in place"):
        write_scene_house("box_after_turn", tmp_path, path=l_path()[:21])  # one straight leg
