"""sim2d: a pymunk house with a raycast perspective camera, for visual teach & repeat.

Public API (see docs/ARCHITECTURE.md)::

    from vtr.sim2d import Simulator, SimConfig, CameraConfig, Pose, load_house

Names are imported lazily so that `vtr sim --help` does not import pymunk.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

__all__ = [
    "CameraConfig",
    "House",
    "HouseError",
    "Pose",
    "SimConfig",
    "Simulator",
    "load_house",
    "load_route",
    "list_routes",
    "Route",
]

_WHERE = {
    "CameraConfig": "vtr.sim2d.config",
    "SimConfig": "vtr.sim2d.config",
    "Pose": "vtr.sim2d.config",
    "House": "vtr.sim2d.house",
    "HouseError": "vtr.sim2d.house",
    "load_house": "vtr.sim2d.house",
    "Simulator": "vtr.sim2d.simulator",
    "Route": "vtr.sim2d.routes",
    "load_route": "vtr.sim2d.routes",
    "list_routes": "vtr.sim2d.routes",
}

if TYPE_CHECKING:
    from vtr.sim2d.config import CameraConfig, Pose, SimConfig
    from vtr.sim2d.house import House, HouseError, load_house
    from vtr.sim2d.routes import Route, list_routes, load_route
    from vtr.sim2d.simulator import Simulator


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        import importlib

        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'vtr.sim2d' has no attribute {name!r}")
