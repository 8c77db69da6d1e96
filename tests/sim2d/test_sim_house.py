"""House loading and validation, geometry queries, and camera layering on a tiny hand-made house."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from vtr.sim2d import CameraConfig, HouseError, Pose, SimConfig, Simulator, load_house


def tiny_house() -> dict:
    """One 4 m x 4 m room with solid blue walls, a solid red box 1 m in front of the start, white ceiling."""
    blue = {"kind": "solid", "colors": [[0, 0, 255]], "grain": 0.0}
    return {
        "name": "tiny",
        "wall_thickness": 0.1,
        "ceiling_color": [255, 255, 255],
        "door_texture": "blue",
        "floor": {"tile": 0.3, "seed": 1, "grout": [0, 0, 0]},
        "textures": {"blue": blue, "red": {"kind": "solid", "colors": [[255, 0, 0]], "grain": 0.0}},
        "rooms": [
            {
                "name": "room",
                "polygon": [[0, 0], [4, 0], [4, 4], [0, 4]],
                "walls": {"n": "blue", "e": "blue", "s": "blue", "w": "blue"},
            }
        ],
        "walls": [[[0, 0], [4, 0]], [[4, 0], [4, 4]], [[4, 4], [0, 4]], [[0, 4], [0, 0]]],
        "furniture": [
            {
                "name": "box",
                "shape": "box",
                "center": [2.5, 2.0],
                "size": [0.4, 1.0],
                "height": 0.8,
                "texture": "red",
            }
        ],
        "start_poses": [{"name": "start", "x": 1.0, "y": 2.0, "yaw": 0.0}],
    }


def write(tmp_path, data, name="h.json"):
    p = tmp_path / name
    p.write_text(json.dumps(data))
    return p


def test_default_house_has_rooms_doors_furniture_and_free_starts():
    h = load_house("house")
    assert len(h.rooms) >= 4
    assert 8 <= len(h.furniture) <= 15
    assert {f.shape for f in h.furniture} == {"box", "polygon", "circle"}
    for p in h.start_poses:
        assert h.room_at(p.x, p.y) is not None
        assert h.is_free(p.x, p.y, 0.2)
    x0, y0, x1, y1 = h.bounds
    assert x1 - x0 >= 8 and y1 - y0 >= 6
    assert not h.is_free(6.0, 1.0, 0.1)  # inside the living/kitchen wall
    assert h.is_free(6.0, 2.05, 0.17)  # the doorway in that wall
    assert not h.is_free(-1.0, 1.0, 0.1)  # outside
    assert h.room_at(-1.0, 1.0) is None
    assert h.room_at(2.0, 2.0) == "living" and h.room_at(8.0, 6.0) == "office"
    # Each room's four walls carry different textures, so that rotation is observable.
    names = {h.texture_names[t] for t in h.segments.texture[h.segments.is_wall]}
    assert len(names) >= 16


def test_floor_mosaic_is_deterministic_and_colourful():
    a = load_house("house").floor_image
    assert a.shape == (512, 512, 3) and a.dtype == np.uint8
    assert len(np.unique(a.reshape(-1, 3), axis=0)) > 200  # many tiles of different colours
    from vtr.sim2d.textures import mosaic_floor

    b = mosaic_floor(0, 0, 10.3, 64, 0.3, 7, np.array([55.0, 55, 60]))
    c = mosaic_floor(0, 0, 10.3, 64, 0.3, 7, np.array([55.0, 55, 60]))
    d = mosaic_floor(0, 0, 10.3, 64, 0.3, 8, np.array([55.0, 55, 60]))
    assert np.array_equal(b, c) and not np.array_equal(b, d)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.pop("rooms"), "rooms: missing required field"),
        (lambda d: d["furniture"][0].update(texture="gold"), "furniture[0].texture"),
        (lambda d: d["furniture"][0].update(shape="cone"), "'box', 'polygon' or 'circle'"),
        (lambda d: d["textures"]["red"].update(kind="plaid"), "textures.red.kind"),
        (lambda d: d["rooms"][0]["walls"].pop("e"), "rooms[0].walls.e: missing"),
        (lambda d: d.update(wall_thickness=-1), "wall_thickness"),
        (lambda d: d["start_poses"][0].update(x=2.5), "start_poses[0]: (2.5, 2.0) is not free"),
        (lambda d: d["start_poses"][0].update(yaw="north"), "start_poses[0].yaw: expected a finite number"),
        (lambda d: d.update(ceiling_color=[300, 0, 0]), "ceiling_color"),
        (lambda d: d["walls"].append([[1, 1]]), "walls[4]"),
        (
            lambda d: d["furniture"].append(
                {
                    "name": "L",
                    "shape": "polygon",
                    "points": [[3, 3], [3.5, 3], [3.2, 3.2], [3.5, 3.5], [3, 3.5]],
                    "height": 1.0,
                    "texture": "red",
                }
            ),
            "must be convex",
        ),
    ],
)
def test_house_validation_names_the_bad_field(tmp_path, mutate, message):
    data = copy.deepcopy(tiny_house())
    mutate(data)
    with pytest.raises(HouseError) as err:
        load_house(write(tmp_path, data))
    assert message in str(err.value)
    assert "h.json" in str(err.value)


def test_house_file_errors(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"name": "x",')
    with pytest.raises(HouseError, match="invalid JSON at line 1"):
        load_house(bad)
    with pytest.raises(HouseError, match="unknown house 'mansion'"):
        load_house("mansion")
    with pytest.raises(HouseError, match="not found"):
        load_house(tmp_path / "missing.json")
    lst = tmp_path / "list.json"
    lst.write_text("[]")
    with pytest.raises(HouseError, match="top level must be a JSON object"):
        load_house(lst)
    assert load_house(write(tmp_path, tiny_house())).name == "tiny"


def test_camera_layers_furniture_wall_floor_ceiling(tmp_path):
    path = write(tmp_path, tiny_house())
    cam = CameraConfig(width=64, height=64, ambient=1.0)  # ambient 1: no distance shading, exact colours
    sim = Simulator(SimConfig(house=str(path), camera=cam))
    img = sim.reset(Pose(1.0, 2.0, 0.0)).astype(int)
    col = img[:, 32]
    f = cam.focal_px
    row_of = lambda z, d: int(32 - f * (z - cam.camera_height) / d)  # noqa: E731
    # The box face is at 2.3 m (0.8 m high), the wall face at 3.95 m (2.5 m high).
    assert tuple(col[row_of(0.5, 1.3)]) == (255, 0, 0)  # box
    assert tuple(col[row_of(1.5, 2.95)]) == (0, 0, 255)  # wall above the box
    assert tuple(col[0]) == (255, 255, 255)  # ceiling above the wall
    floor = col[row_of(0.0, 1.3) + 3 :]
    assert floor.shape[0] > 5 and not np.any(np.all(floor == (255, 0, 0), axis=1))  # the floor, not the box
    # Looking away from the box: only the wall, floor and ceiling.
    back = sim.reset(Pose(1.0, 2.0, math.pi))
    assert not np.any(np.all(back == (255, 0, 0), axis=-1))


def test_camera_must_stay_below_the_walls(tmp_path):
    path = write(tmp_path, tiny_house())
    with pytest.raises(ValueError, match=r"camera_height \(2.5\) must be below wall_height"):
        Simulator(SimConfig(house=str(path), camera=CameraConfig(camera_height=2.5)))
