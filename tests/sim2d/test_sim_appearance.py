"""Appearance changes: each kind changes what the camera sees (or the geometry), and bad specs fail clearly."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from vtr.sim2d import CameraConfig, SimConfig, Simulator
from vtr.sim2d.appearance import Change, apply_changes, parse_change
from vtr.sim2d.house import house_data, load_house

CAM = CameraConfig(width=48, height=48)


def view(house: str = "house", changes: tuple[str, ...] = (), pose=None) -> np.ndarray:
    sim = Simulator(SimConfig(house=house, changes=changes, camera=CAM))
    return sim.reset(pose).astype(np.float64)


def test_parse_round_trip_and_errors():
    c = parse_change("light:dark=w,0.5")
    assert c == Change("light", "dark", "w,0.5") and str(c) == "light:dark=w,0.5"
    assert parse_change(c) == c
    for bad in (
        "bogus",
        "paint:x=1",
        "light:level=x",
        "light:dark=q,0.5",
        "retexture:wall=-1",
        "obstacle:1=0.3",
    ):
        with pytest.raises(ValueError, match="bad change"):
            parse_change(bad)
    with pytest.raises(ValueError, match="bad change"):
        SimConfig(changes=("move:sofa",))


def test_retexture_one_wall_changes_exactly_one_texture():
    data, _ = house_data("house")
    new = apply_changes(data, ["retexture:wall=1"])
    changed = [n for n in data["textures"] if data["textures"][n] != new["textures"][n]]
    walls = {t for r in data["rooms"] for t in r["walls"].values()}
    assert len(changed) == 1 and changed[0] in walls


def test_input_map_is_not_modified():
    data, _ = house_data("house")
    before = json.dumps(data, sort_keys=True)
    apply_changes(data, ["retexture:walls=1", "move:sofa=0.3", "light:level=0.5", "floor:living=2"])
    assert json.dumps(data, sort_keys=True) == before


def test_light_changes_brightness_colour_and_one_side():
    base = view()
    assert view(changes=("light:level=0.5",)).mean() < 0.6 * base.mean()
    warm = view(changes=("light:tint=1.0,1.0,0.6",))
    assert (
        warm[..., 2].mean() < 0.7 * base[..., 2].mean() and abs(warm[..., 0].mean() - base[..., 0].mean()) < 1
    )
    # Living room is at the west of the house: darkening the west side darkens its view, the east less so.
    west = view(changes=("light:dark=w,0.4",))
    east = view(changes=("light:dark=e,0.4",))
    assert west.mean() < east.mean() < base.mean() + 1e-9


def test_retexture_floor_move_obstacle_change_the_image_and_geometry():
    base = view()
    for change in ("retexture:floor=3", "retexture:walls=1", "floor:living=4", "obstacle:4.0,3.0=0.5"):
        assert np.abs(view(changes=(change,)) - base).mean() > 2.0, change
    moved = load_house("house", ("move:sofa=0.3",))
    original = load_house("house")
    shift = np.subtract(moved.furniture[0].center, original.furniture[0].center)
    assert abs(np.hypot(*shift) - 0.3) < 1e-6
    blocked = load_house("house", ("obstacle:4.0,3.0=0.5",))
    assert original.is_free(4.0, 3.0, 0.1) and not blocked.is_free(4.0, 3.0, 0.1)


def test_impossible_changes_are_refused():
    with pytest.raises(ValueError, match="cover a start pose"):
        load_house("house", ("obstacle:2.8,3.0=0.4",))  # the living room start pose
    with pytest.raises(ValueError, match="cannot move"):
        load_house("house", ("move:sofa=0,-2",))  # through the south wall
    with pytest.raises(ValueError, match="no furniture named"):
        load_house("house", ("move:piano=0.3",))


def test_changes_work_on_procedural_houses_too():
    data, _ = house_data("random:5")
    piece = data["furniture"][0]["name"]
    changes = ("retexture:wall=2", f"move:{piece}=0.2", "light:dark=n,0.5")
    assert np.abs(view("random:5", changes) - view("random:5")).mean() > 0.5


def test_cli_snapshot_reports_bad_change_in_one_line(tmp_path):
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "vtr.cli",
            "sim",
            "snapshot",
            "--change",
            "bogus",
            "--out",
            str(tmp_path / "a.png"),
        ],
        capture_output=True,
        text=True,
    )
    assert out.returncode == 2 and out.stderr.count("\n") == 1 and "bad change" in out.stderr
