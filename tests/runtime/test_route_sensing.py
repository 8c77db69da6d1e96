"""What a route's camera meta tells the floor geometry (runtime.route_sensing.floor_camera)."""

from __future__ import annotations

import pytest

from vtr.runtime.floor_view import Camera
from vtr.runtime.route_sensing import floor_camera


def test_the_camera_height_is_read_under_either_name():
    """Routes taught on the simulator (and older bridges) record the camera's height as ``camera_height``,
    the name hello still reads (deprecated) for ``height_m``: the floor geometry read only ``height_m``, so a
    0.20 m or 0.55 m camera was warped and registered as one at 0.30 m."""
    assert floor_camera({"fov_deg": 90.0, "camera_height": 0.2}).height_m == pytest.approx(0.2)
    assert floor_camera({"fov_deg": 70.0, "height_m": 0.55}).height_m == pytest.approx(0.55)
    both = floor_camera({"fov_deg": 70.0, "height_m": 0.4, "camera_height": 0.2})
    assert both.height_m == pytest.approx(0.4) and both.fov_deg == pytest.approx(70.0)


def test_what_the_meta_does_not_say_is_the_shipped_camera():
    base = Camera()
    assert floor_camera({}) == base
    assert floor_camera({"fov_deg": "wide", "camera_height": -1.0, "height_m": None}) == base
    assert floor_camera({"camera_height": True}).height_m == base.height_m


def test_a_route_taught_on_the_simulator_records_its_camera_height_under_the_current_name():
    """The evaluation teaches in-process (the simulator's info, not a hello): its routes recorded
    ``camera_height``, so every evaluation at another height ran a floor geometry at 0.30 m that a robot
    announcing ``height_m`` (as `vtr teach` records from a checked hello) never runs."""
    from vtr.evaluation.harness import teach
    from vtr.sim2d.routes import ROUTES_DIR

    route, _ = teach(ROUTES_DIR / "translation.json", (64, 64), 0.1, camera=(90.0, 0.45))
    assert route.camera["height_m"] == pytest.approx(0.45) and "camera_height" not in route.camera
    assert floor_camera(route.camera).height_m == pytest.approx(0.45)
