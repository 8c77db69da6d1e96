"""Cameras across the range robots carry: fields of view, heights, furniture seen from above, bad values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_sim_house import tiny_house

from vtr.sim2d import CameraConfig, SimConfig, Simulator
from vtr.sim2d.camera import Camera
from vtr.sim2d.config import camera_config
from vtr.sim2d.house import House, load_house


@pytest.mark.parametrize("fov", [60.0, 90.0, 120.0])
@pytest.mark.parametrize("height", [0.15, 0.3, 0.6])
def test_every_fov_and_height_renders(fov, height):
    cam = Camera(load_house("house"), camera_config(48, 32, (fov, height)))
    img = cam.render(2.8, 3.0, 0.5)
    assert img.shape == (32, 48, 3) and img.dtype == np.uint8
    assert img.std() > 10  # a scene, not a flat colour


def test_wider_fov_sees_more_and_higher_camera_sees_more_floor():
    house = load_house("house")
    pose = (2.8, 3.0, 0.5)
    narrow = Camera(house, camera_config(64, 64, (60.0, 0.3))).raycast(*pose)
    wide = Camera(house, camera_config(64, 64, (120.0, 0.3))).raycast(*pose)
    # the edge columns of a wider camera look further to the side
    assert abs(math.atan2(wide["dy"][0], wide["dx"][0]) - pose[2]) > abs(
        math.atan2(narrow["dy"][0], narrow["dx"][0]) - pose[2]
    ) + math.radians(25)
    # the horizon stays in the middle; a camera at 0.6 m sees the floor nearer the horizon than one at 0.15 m
    low = Camera(house, camera_config(64, 64, (90.0, 0.15)))
    high = Camera(house, camera_config(64, 64, (90.0, 0.6)))
    assert high.floor_row0 == low.floor_row0 == 32


def _low_table_house(height: float = 0.45) -> House:
    data = tiny_house()
    data["furniture"][0]["height"] = height  # a low red table 2.3..2.7 x 1.5..2.5; blue walls behind it
    return House(data, "tiny_table")


def test_a_low_table_seen_from_above_shows_its_top():
    house = _low_table_house(0.45)
    cfg = CameraConfig(camera_height=0.5)
    cam = Camera(house, cfg)
    x0, y0 = 1.9, 2.0
    img = cam.render(x0, y0, 0.0)
    top_colours = {tuple(c) for c in cam.atlas[cam._top_tab[0]].view(np.uint8).reshape(-1, 3)}
    f, n = cfg.focal_px, cfg.width
    rows, cols = np.mgrid[0:n, 0:n]
    yr = (rows + 0.5 - n / 2) / f
    xc = (cols + 0.5 - n / 2) / f
    depth = np.where(yr > 0, (cfg.camera_height - 0.45) / np.maximum(yr, 1e-9), np.inf)
    px, py = x0 + depth, y0 - depth * xc  # where each pixel's ray meets the table's top plane
    inside = (yr > 0) & (px > 2.3 + 0.02) & (px < 2.7 - 0.02) & (np.abs(py - 2.0) < 0.5 - 0.02)
    assert inside.sum() > 50  # the top covers a band of rows below the horizon
    seen = [tuple(img[r, c]) for r, c in zip(*np.nonzero(inside), strict=True)]
    assert all(c in top_colours for c in seen)
    assert all(c[0] > 150 and c[2] == 0 for c in seen)  # red (the table), not the blue wall behind
    # above the top's far edge the column looks past the table: the wall behind it, blue
    r_far = int(np.floor(n / 2 - 0.5 + f * 0.05 / (2.7 - x0))) - 2
    assert img[r_far, n // 2, 2] > 150 and img[r_far, n // 2, 0] == 0


def test_a_camera_below_every_top_draws_what_it_drew_before():
    """Below every piece the renderer takes its former path: two layers, no tops."""
    house = _low_table_house(0.45)
    cam = Camera(house, CameraConfig(camera_height=0.3))
    assert not cam.tops and cam.raycast(1.9, 2.0, 0.0)["depth"].shape[0] == 2
    assert Camera(house, CameraConfig(camera_height=0.5)).tops


def test_a_piece_behind_a_low_one_shows_above_it():
    """A camera above a low table keeps the second piece: a taller box behind the table shows over it."""
    data = tiny_house()
    data["furniture"][0]["height"] = 0.3
    data["furniture"].append(
        {
            "name": "tall",
            "shape": "box",
            "center": [3.3, 2.0],
            "size": [0.3, 1.0],
            "height": 1.2,
            "texture": "blue",
        }
    )
    data["textures"]["green"] = {"kind": "solid", "colors": [[0, 255, 0]], "grain": 0.0}
    for side in "nesw":
        data["rooms"][0]["walls"][side] = "green"
    data["door_texture"] = "green"
    cam = Camera(House(data, "two_pieces"), CameraConfig(camera_height=0.5))
    col = cam.render(1.9, 2.0, 0.0)[:, 64]
    # the tall blue box (3.15 m) fills rows above the table's top and below the green wall's
    assert np.any((col[:, 2] > 150) & (col[:, 1] == 0))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"fov_deg": 0.5}, r"fov_deg must be in \[1, 170\]"),
        ({"fov_deg": 175.0}, r"fov_deg must be in \[1, 170\]"),
        ({"camera_height": 0.0}, "camera_height must be a finite number > 0"),
        ({"camera_height": float("nan")}, "camera_height must be a finite number > 0"),
        ({"camera_height": 3.0}, "must be below wall_height"),
        ({"width": 0}, "width must be an integer >= 1"),
    ],
)
def test_bad_camera_values_are_one_line_errors(kwargs, message):
    with pytest.raises(ValueError, match=message) as err:
        CameraConfig(**kwargs)
    assert "\n" not in str(err.value)


def test_simulator_renders_at_the_cameras_native_resolution():
    sim = Simulator(SimConfig(camera=camera_config(160, 120, (70.0, 0.45))))
    assert sim.observe().shape == (120, 160, 3)
    info = sim.info()["camera"]
    assert (info["fov_deg"], info["camera_height"]) == (70.0, 0.45)
