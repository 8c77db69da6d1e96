"""Furniture that moves during a run (sim2d.moving, Simulator.move_furniture): what the camera, the scan
and the physics see equals a house loaded with the piece there."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vtr.sim2d import SimConfig, Simulator
from vtr.sim2d.config import Pose
from vtr.sim2d.house import resolve_house_path

BOX = {
    "name": "crate",
    "shape": "box",
    "center": [3.0, 3.0],
    "size": [0.25, 0.25],
    "height": 0.4,
    "texture": "metal_blue",
    "angle_deg": 30.0,
}
ROBOT = Pose(2.2, 3.0, 0.0)  # in the living room, facing +x


def house_with_box(tmp_path, center: list[float], name: str) -> str:
    data = json.loads(resolve_house_path("house").read_text(encoding="utf-8"))
    data["furniture"].append({**BOX, "center": center})
    data["start_poses"] = [p for p in data["start_poses"] if abs(p["x"] - 2.8) + abs(p["y"] - 3.2) > 1.0]
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(data), encoding="utf-8")
    return str(path)


def test_a_moved_piece_renders_scans_and_collides_as_if_loaded_there(tmp_path):
    moving = Simulator(SimConfig(house=house_with_box(tmp_path, [3.0, 3.6], "start")))
    loaded = Simulator(SimConfig(house=house_with_box(tmp_path, [2.7, 3.05], "there")))
    moving.reset(ROBOT)
    loaded.reset(ROBOT)
    before = moving.observe()
    moving.move_furniture("crate", (2.7, 3.05))
    assert not np.array_equal(before, moving.observe())
    assert np.array_equal(moving.observe(), loaded.observe())
    assert np.array_equal(moving.scan().ranges, loaded.scan().ranges)
    assert moving.time == 0.0 and moving.pose == pytest.approx(ROBOT)
    for sim in (moving, loaded):  # driving into it: the same contact
        for _ in range(10):
            sim.step(0.3, 0.0, 0.1)
    assert moving.collided and loaded.collided and moving.pose == pytest.approx(loaded.pose)


def test_a_piece_is_not_moved_onto_the_robot_or_found_by_a_wrong_name(tmp_path):
    sim = Simulator(SimConfig(house=house_with_box(tmp_path, [3.0, 3.6], "start")))
    sim.reset(ROBOT)
    with pytest.raises(ValueError, match="overlap the robot"):
        sim.move_furniture("crate", (2.3, 3.0))
    with pytest.raises(ValueError, match="no furniture named"):
        sim.move_furniture("sofa_that_is_not_there", (2.3, 3.0))
    assert sim.house.furniture[-1].center == (3.0, 3.6)


def test_set_house_gives_the_scan_the_new_house(tmp_path):
    sim = Simulator(SimConfig(house=house_with_box(tmp_path, [2.7, 3.0], "boxed")))
    sim.reset(ROBOT)
    near = float(np.min(sim.scan().ranges))
    sim.set_house(str(resolve_house_path("house")))
    assert float(np.min(sim.scan().ranges)) > near + 0.1
