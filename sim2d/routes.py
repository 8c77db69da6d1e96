"""The scripted routes shipped with the house (sim2d/routes/*.json).

The ROUTE.json format and its validation live in one place, `runtime.route_script` (the robot side needs
them for `vtr teach`); this module only finds the shipped files by name.
"""

from __future__ import annotations

import os
from pathlib import Path

from vtr.runtime.route_script import RouteScript as Route
from vtr.runtime.route_script import Segment, load_route_script

__all__ = ["ROUTES_DIR", "Route", "Segment", "list_routes", "load_route"]

ROUTES_DIR = Path(__file__).resolve().parent / "routes"


def list_routes() -> list[str]:
    """Names of the routes shipped in sim2d/routes."""
    return sorted(p.stem for p in ROUTES_DIR.glob("*.json"))


def load_route(name_or_path: str | os.PathLike[str]) -> Route:
    """Load a route by name (sim2d/routes/NAME.json) or path, validating every field."""
    s = os.fspath(name_or_path)
    is_name = "/" not in s and os.sep not in s and not s.endswith(".json")
    path = ROUTES_DIR / f"{s}.json" if is_name else Path(s)
    if not path.is_file():
        raise ValueError(f"route not found: {s!r} (shipped routes: {', '.join(list_routes())})")
    return load_route_script(path)
