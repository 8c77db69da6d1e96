"""Route files (atomic, versioned, validated) and ROUTE.json scripts."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from runtime_fakes import corridor_route

from vtr.runtime.route import Route, RouteError
from vtr.runtime.route_script import RouteScriptError, load_route_script, parse_route_script


def test_route_round_trip(tmp_path):
    route = corridor_route()
    route.poses[3] = np.nan  # an unknown pose survives
    route.camera = {"width": 16, "height": 16}
    route.spacing = {"rule": "steps", "every": 2}
    path = tmp_path / "r.npz"
    route.save(path)
    loaded = Route.load(path)
    np.testing.assert_array_equal(loaded.images, route.images)
    np.testing.assert_array_equal(loaded.poses, route.poses)
    np.testing.assert_array_equal(loaded.commands, route.commands)
    assert loaded.meta_dict() == route.meta_dict()
    assert os.listdir(tmp_path) == ["r.npz"]  # no temporary file left behind


def test_failed_save_leaves_the_old_file_intact(tmp_path, monkeypatch):
    path = tmp_path / "r.npz"
    corridor_route().save(path)
    before = path.read_bytes()

    def boom(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez", boom)
    with pytest.raises(OSError, match="disk full"):
        corridor_route(length_m=0.2).save(path)
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["r.npz"]


@pytest.mark.parametrize(
    "change, fragment",
    [
        (lambda r: setattr(r, "images", r.images.astype(np.float32)), "uint8"),
        (lambda r: setattr(r, "poses", r.poses[:-1]), "poses must be"),
        (lambda r: setattr(r, "commands", np.full_like(r.commands, np.nan)), "NaN or inf"),
        (lambda r: setattr(r, "dt", 0.0), "dt"),
        (lambda r: setattr(r, "format_version", 7), "format version 7"),
    ],
)
def test_route_validation(change, fragment):
    route = corridor_route()
    change(route)
    with pytest.raises(RouteError, match=fragment):
        route.validate()


def test_load_refuses_bad_files(tmp_path):
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"nope")
    with pytest.raises(RouteError, match="not an .npz archive"):
        Route.load(junk)
    partial = tmp_path / "partial.npz"
    np.savez(partial, images=np.zeros((1, 2, 2, 3), np.uint8))
    with pytest.raises(RouteError, match="missing arrays"):
        Route.load(partial)
    route = corridor_route()
    future = tmp_path / "future.npz"
    meta = dict(route.meta_dict(), format_version=99)
    np.savez(
        future,
        images=route.images,
        poses=route.poses,
        commands=route.commands,
        meta=np.array(json.dumps(meta)),
    )
    with pytest.raises(RouteError, match="format version 99"):
        Route.load(future)
    pickled = tmp_path / "pickled.npz"
    np.savez(
        pickled, images=route.images, poses=route.poses, commands=route.commands, meta=np.array([{"a": 1}])
    )
    with pytest.raises(RouteError, match="Python objects"):
        Route.load(pickled)


def test_load_refuses_a_route_that_would_expand_past_the_cap_before_decompressing(tmp_path):
    route = corridor_route()
    bomb = tmp_path / "bomb.npz"
    np.savez_compressed(
        bomb,
        images=np.zeros((2000, 64, 64, 3), np.uint8),  # 24.6 MB of zeros in a few kB
        poses=np.zeros((2000, 3)),
        commands=np.zeros((2000, 2)),
        meta=np.array(json.dumps(route.meta_dict())),
    )
    assert bomb.stat().st_size < 100_000
    with pytest.raises(RouteError, match="more than 4x the file"):
        Route.load(bomb)
    assert len(Route.load(bomb, max_expansion=1e4)) == 2000  # a caller may raise the cap on purpose


def test_a_lying_npy_header_is_refused(tmp_path):
    import zipfile

    liar = tmp_path / "liar.npz"
    with zipfile.ZipFile(liar, "w") as z:
        header = b"\x93NUMPY\x01\x00v\x00{'descr': '|u1', 'fortran_order': False, 'shape': (100000000,), }"
        z.writestr("images.npy", header.ljust(10 + 118) + b"\n" + bytes(10))
    with pytest.raises(RouteError, match="declares 100000000 bytes"):
        Route.load(liar)


def test_route_script_parsing(tmp_path):
    script = parse_route_script(
        {"start": {"x": 1, "y": 2, "yaw": 0.5}, "segments": [{"v": 0.2, "w": 0.0, "duration": 1.5}]}
    )
    assert script.start == (1.0, 2.0, 0.5) and script.duration == 1.5 and script.segments[0].v == 0.2
    path = tmp_path / "translation.json"
    path.write_text(
        json.dumps({"start": {"x": 0, "y": 0, "yaw": 0}, "segments": [{"v": 0, "w": 1, "duration": 1}]})
    )
    assert load_route_script(path).name == "translation"


@pytest.mark.parametrize(
    "data, fragment",
    [
        ([], "JSON object"),
        ({"segments": []}, "'start'"),
        ({"start": {"x": 0, "y": 0}, "segments": [{"v": 0, "w": 0, "duration": 1}]}, "missing 'yaw'"),
        ({"start": {"x": 0, "y": 0, "yaw": 0}, "segments": []}, "non-empty"),
        ({"start": {"x": 0, "y": 0, "yaw": 0}, "segments": [{"v": 0.9, "w": 0, "duration": 1}]}, "v_max"),
        ({"start": {"x": 0, "y": 0, "yaw": 0}, "segments": [{"v": 0, "w": 2, "duration": 1}]}, "w_max"),
        ({"start": {"x": 0, "y": 0, "yaw": 0}, "segments": [{"v": 0, "w": 0, "duration": 0}]}, "duration"),
        ({"start": {"x": "a", "y": 0, "yaw": 0}, "segments": [{"v": 0, "w": 0, "duration": 1}]}, "start.x"),
    ],
)
def test_route_script_errors(data, fragment):
    with pytest.raises(RouteScriptError, match=fragment):
        parse_route_script(data)


def test_route_script_bad_json(tmp_path):
    path = tmp_path / "r.json"
    path.write_text("{")
    with pytest.raises(RouteScriptError, match="not valid JSON"):
        load_route_script(path)


def _poseless(spacing: dict) -> Route:
    """Straight at 0.2 m/s for 4 gaps, then a turn in place at 0.5 rad/s for 3 gaps, then an arc."""
    commands = np.array([[0.2, 0.0]] * 4 + [[0.0, 0.5]] * 3 + [[0.1, 0.25], [0.0, 0.0]])
    n = len(commands)
    images = np.zeros((n, 16, 16, 3), np.uint8)
    return Route(images, np.full((n, 3), np.nan), commands, spacing=spacing)


def test_travel_poses_dead_reckon_a_route_taught_without_poses():
    route = _poseless({"rule": "steps", "every": 2, "dt": 0.1})
    p = route.travel_poses()
    gaps = np.hypot(*np.diff(p[:, :2], axis=0).T)
    np.testing.assert_allclose(gaps[:4], 0.04)  # 0.2 m/s for 2 x 0.1 s
    np.testing.assert_allclose(gaps[4:7], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.diff(p[:, 2])[4:7], 0.1)  # 0.5 rad/s for 0.2 s
    # the arc: chord of a 0.02 m arc of radius 0.4 m, heading turned by 0.05 rad
    assert gaps[7] == pytest.approx(2 * 0.4 * np.sin(0.025)) and np.diff(p[:, 2])[7] == pytest.approx(0.05)
    assert _poseless({"rule": "image", "min_image_change": 5.0}).travel_poses() is None
    known = corridor_route()
    assert known.travel_poses() is known.poses


def test_a_route_without_poses_is_still_gated():
    from vtr.runtime.controller import Controller, ControllerConfig

    route = _poseless({"rule": "steps", "every": 2, "dt": 0.1})
    blind = Controller(route.images, ControllerConfig(), route.commands, route.poses).gate
    assert blind is not None and np.isnan(blind.distance[1])  # NaN poses: the gate never holds a switch
    gated = Controller(route.images, ControllerConfig(), route.commands, route.poses, route.travel_poses())
    assert gated.gate is not None and gated.gate.distance[1] == pytest.approx(0.04)
    assert gated.gate.turn[5] == pytest.approx(0.1)


def test_the_taught_clearance_travels_with_the_route(tmp_path):
    from vtr.runtime.route import Route, RouteError

    n = 3
    images = np.zeros((n, 8, 8, 3), dtype=np.uint8)
    clearance = np.array([1.2, np.inf, np.nan])
    route = Route(images=images, poses=np.zeros((n, 3)), commands=np.zeros((n, 2)), clearance=clearance)
    route.save(tmp_path / "r.npz")
    back = Route.load(tmp_path / "r.npz")
    np.testing.assert_array_equal(back.clearance, clearance)
    plain = Route(images=images, poses=np.zeros((n, 3)), commands=np.zeros((n, 2)))
    plain.save(tmp_path / "p.npz")
    assert Route.load(tmp_path / "p.npz").clearance is None
    with pytest.raises(RouteError, match="clearance"):
        Route(
            images=images, poses=np.zeros((n, 3)), commands=np.zeros((n, 2)), clearance=np.array([-1.0] * n)
        )
