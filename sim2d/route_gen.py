"""Taught routes for any house, from (house, route seed): what a user would drive with `vtr teach`.

``generate_route("random:5000", 2)`` returns a ``RouteScript`` (the ROUTE.json format of
runtime.route_script; ``route_json`` gives the file's dict). A route starts at a free pose, goes through 1-3
rooms by their doorways, and is made of straight runs (creeping, normal or fast), arcs and turns in place,
within the robot's limits (runtime.contracts), and ends with a turn to face something now and then.

How: a clearance grid of the house (sim2d.route_plan), a shortest path that prefers open floor from a
random start to a goal 1.5-6.5 m away in the wanted number of rooms, shortcut into a polyline that keeps
PLAN_CLEARANCE (robot radius 0.17 m + 0.13 m) from walls and furniture; each corner becomes an arc that
fits between its legs and stays as clear, or a turn in place (always safe: the robot is a disc). Every
piece lasts a whole number of control steps (CONTROL_DT), with its speed adjusted so that the distance and
angle are exact, because `vtr teach` drives a segment as round(duration / dt) steps. Finally the script is
driven noise-free through the simulator's physics: a route that touches anything, passes closer than
VERIFY_CLEARANCE, or ends away from the planned end is discarded and another is drawn.

Deterministic: the same (house, seed) gives the same route on every machine (numpy's seeded generator).
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime.contracts import CONTROL_DT, LIMITS
from vtr.runtime.route_script import RouteScript, Segment
from vtr.sim2d.config import Pose, SimConfig
from vtr.sim2d.house import RANDOM_PREFIX, House, load_house
from vtr.sim2d.physics import advance, build_world, pose_of
from vtr.sim2d.route_plan import ClearanceGrid, clearance_grid, line_clearance, search, shortcut, simplify

ROBOT_RADIUS = SimConfig().robot_radius
PLAN_CLEARANCE = ROBOT_RADIUS + 0.13  # m the planned path keeps from walls and furniture
OPEN_CLEARANCE = 0.45  # m: shortcuts keep this much where the searched path had it
START_CLEARANCE = 0.40  # m around start and goal points
VERIFY_CLEARANCE = ROBOT_RADIUS + 0.08  # m the noise-free drive must keep (true geometry)
END_TOLERANCE = 0.05  # m between the driven and the planned end point
MAX_DURATION = 40.0  # s
#: Rooms visited -> (probability, path length range in metres).
ROOM_PLANS = {1: (0.35, (1.5, 3.5)), 2: (0.45, (2.5, 5.0)), 3: (0.20, (3.5, 6.5))}
ATTEMPTS = 30


@dataclass(frozen=True)
class DriveCheck:
    """What a noise-free drive of a script did."""

    touched: bool  # the robot touched a wall or furniture
    min_clearance: float  # m, smallest distance of the robot's centre to anything
    end: tuple[float, float, float]
    poses: np.ndarray  # (N, 3) the pose after every control step, start included


def _house_stem(house: str) -> str:
    """A map file is known by its name (its folder does not change the routes), anything else as given."""
    return Path(house).stem if house.endswith(".json") else house


def house_key(house: str) -> int:
    """A stable integer for a house: the SEED of random:SEED, else a CRC of the map's name."""
    if house.startswith(RANDOM_PREFIX) and house[len(RANDOM_PREFIX) :].isdigit():
        return int(house[len(RANDOM_PREFIX) :])
    return zlib.crc32(_house_stem(house).encode("utf-8"))


def route_name(house: str, seed: int) -> str:
    """e.g. random5000_r2 or house_r0 (no colon: the name doubles as a file stem)."""
    return f"{_house_stem(house).replace(RANDOM_PREFIX, 'random').replace(':', '')}_r{seed}"


# ------------------------------------------------------------------------------------------ pieces


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _steps(amount: float, rate: float, dt: float) -> int:
    return max(1, int(round(abs(amount) / (rate * dt))))


def straight(length: float, v: float, dt: float) -> Segment:
    """Drive ``length`` m forward in whole control steps, near ``v`` m/s (never above V_MAX)."""
    n = _steps(length, v, dt)
    while length / (n * dt) > LIMITS.v_max:
        n += 1
    return Segment(round(length / (n * dt), 5), 0.0, round(n * dt, 6))


def turn(angle: float, w: float, dt: float) -> Segment:
    """Turn in place by ``angle`` rad (sign: counter-clockwise) in whole steps, near |w| rad/s."""
    n = _steps(angle, w, dt)
    while abs(angle) / (n * dt) > LIMITS.w_max:
        n += 1
    return Segment(0.0, round(angle / (n * dt), 5), round(n * dt, 6))


def arc(angle: float, radius: float, v: float, dt: float) -> Segment:
    """Drive an arc of ``radius`` m through ``angle`` rad at about ``v`` m/s, within both limits."""
    n = _steps(abs(angle) * radius, v, dt)
    while abs(angle) / (n * dt) > LIMITS.w_max or abs(angle) * radius / (n * dt) > LIMITS.v_max:
        n += 1
    w = angle / (n * dt)
    return Segment(round(float(abs(w) * radius), 5), round(float(w), 5), round(n * dt, 6))


def _speed(rng: np.random.Generator, length: float) -> float:
    """A straight run's speed: creeping now and then (short runs only), mostly normal, sometimes fast."""
    u = rng.random()
    if u < 0.2 and length <= 1.0:
        return float(rng.uniform(0.06, 0.12))
    if u < 0.8:
        return float(rng.uniform(0.18, 0.35))
    return float(rng.uniform(0.38, 0.45))


def _runs(length: float, rng: np.random.Generator, dt: float) -> list[Segment]:
    """A straight leg as one run, or (longer legs, sometimes) two runs at different speeds."""
    if length > 1.2 and rng.random() < 0.4:
        first = float(rng.uniform(0.3, 0.7)) * length
        return [
            straight(first, _speed(rng, first), dt),
            straight(length - first, _speed(rng, length - first), dt),
        ]
    return [straight(length, _speed(rng, length), dt)]


def bend(grid: ClearanceGrid, pts: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Sometimes add a sideways waypoint to long legs, so that straight-line routes get curves too."""
    out = [pts[0]]
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        length = float(np.hypot(*(b - a)))
        if length > 1.5 and rng.random() < (0.8 if len(pts) == 2 else 0.4):
            normal = np.array([-(b - a)[1], (b - a)[0]]) / length
            for _ in range(6):
                mid = a + float(rng.uniform(0.3, 0.7)) * (b - a)
                mid = mid + float(rng.choice([-1.0, 1.0]) * rng.uniform(0.25, 0.7)) * normal
                if min(line_clearance(grid, a, mid), line_clearance(grid, mid, b)) >= PLAN_CLEARANCE:
                    out.append(mid)
                    break
        out.append(b)
    return np.asarray(out)


def _arc_points(corner: np.ndarray, h_in: float, delta: float, radius: float) -> np.ndarray:
    """Points along the fillet arc of ``radius`` at a corner where the heading changes by ``delta``."""
    t = radius * math.tan(abs(delta) / 2)
    start = corner - t * np.array([math.cos(h_in), math.sin(h_in)])
    side = 1.0 if delta > 0 else -1.0
    centre = start + side * radius * np.array([-math.sin(h_in), math.cos(h_in)])
    phis = h_in - side * math.pi / 2 + np.linspace(0.0, delta, 24)
    return centre + radius * np.stack([np.cos(phis), np.sin(phis)], axis=1)


def polyline_segments(
    grid: ClearanceGrid, pts: np.ndarray, rng: np.random.Generator, dt: float = CONTROL_DT
) -> tuple[float, list[Segment]]:
    """(start yaw, segments) that drive the polyline ``pts``: straight legs, corners as arcs or turns."""
    legs = np.diff(pts, axis=0)
    lengths = np.hypot(legs[:, 0], legs[:, 1])
    heads = np.arctan2(legs[:, 1], legs[:, 0])
    n = len(legs)
    cut_in, cut_out = np.zeros(n), np.zeros(n)  # metres an arc takes from each leg's start / end
    corners: list[Segment] = []
    for i in range(1, n):
        delta = _wrap(float(heads[i] - heads[i - 1]))
        room = min(lengths[i - 1] * (0.9 if i == 1 else 0.5), lengths[i] * (0.9 if i == n - 1 else 0.5))
        radius = min(float(rng.uniform(0.4, 1.2)), room / max(math.tan(abs(delta) / 2), 1e-6))
        seg = None
        if abs(delta) <= math.radians(100) and rng.random() > 0.3:
            while radius >= 0.3 and seg is None:
                pts_arc = _arc_points(pts[i], float(heads[i - 1]), delta, radius)
                if grid.clearance_at(pts_arc).min() >= PLAN_CLEARANCE:
                    seg = arc(delta, radius, float(rng.uniform(0.15, 0.3)), dt)
                    cut_out[i - 1] = cut_in[i] = radius * math.tan(abs(delta) / 2)
                else:
                    radius *= 0.7
        corners.append(seg if seg is not None else turn(delta, float(rng.uniform(0.4, 0.7)), dt))
    yaw0 = float(heads[0])
    segments: list[Segment] = []
    if rng.random() < 0.3:  # start facing elsewhere: the route begins with a turn in place
        offset = float(rng.choice([-1.0, 1.0]) * rng.uniform(math.radians(40), math.radians(120)))
        yaw0 = _wrap(yaw0 - offset)
        segments.append(turn(offset, float(rng.uniform(0.4, 0.7)), dt))
    for i in range(n):
        run = float(lengths[i] - cut_in[i] - cut_out[i])
        if run > 0.02:
            segments += _runs(run, rng, dt)
        if i < n - 1:
            segments.append(corners[i])
    if rng.random() < 0.3:  # end turning to face something, as one does at a destination
        final = float(rng.choice([-1.0, 1.0]) * rng.uniform(math.radians(45), math.radians(120)))
        segments.append(turn(final, float(rng.uniform(0.4, 0.7)), dt))
    return yaw0, segments


# ------------------------------------------------------------------------------------------ planning


def _pick(rng: np.random.Generator, cells: np.ndarray) -> tuple[int, int]:
    r, c = cells[int(rng.integers(len(cells)))]
    return int(r), int(c)


def plan_polyline(grid: ClearanceGrid, rng: np.random.Generator) -> np.ndarray | None:
    """A clear polyline from a random start to a goal in 1-3 rooms (None when this draw finds none)."""
    open_cells = grid.clear >= START_CLEARANCE
    rooms = [i for i in range(len(grid.room_names)) if np.any(open_cells & (grid.room == i))]
    if not rooms:
        return None
    room = rooms[int(rng.integers(len(rooms)))]  # a room first, so small rooms are started from too
    start = _pick(rng, np.argwhere(open_cells & (grid.room == room)))
    ks = list(ROOM_PLANS)
    first = int(rng.choice(ks, p=[ROOM_PLANS[k][0] for k in ks]))
    tree = search(grid, start, PLAN_CLEARANCE, max(r[1][1] for r in ROOM_PLANS.values()))
    for k in sorted(ks, key=lambda k: (abs(k - first), -k)):  # else the nearest count of rooms
        lo, hi = ROOM_PLANS[k][1]
        ok = open_cells & (tree.room_changes == k - 1) & (tree.length >= lo) & (tree.length <= hi)
        if np.any(ok):
            cells = tree.path(_pick(rng, np.argwhere(ok)))
            poly = simplify(grid, shortcut(grid, cells, PLAN_CLEARANCE, OPEN_CLEARANCE), PLAN_CLEARANCE)
            return bend(grid, poly, rng)
    return None


def drive(house: House, script: RouteScript, dt: float = CONTROL_DT) -> DriveCheck:
    """Drive ``script`` noise-free through the simulator's physics, as `vtr teach` does (no rendering)."""
    cfg = SimConfig()
    world = build_world(house, Pose(*script.start), ROBOT_RADIUS)
    poses = [tuple(pose_of(world))]
    touched = False
    for seg in script.segments:
        for _ in range(max(1, round(seg.duration / dt))):
            touched |= advance(world, seg.v, seg.w, dt, cfg.physics_dt)
            poses.append(tuple(pose_of(world)))
    arr = np.asarray(poses)
    min_clear = float(house.clearances(arr[:, :2]).min())
    return DriveCheck(touched, min_clear, tuple(float(v) for v in arr[-1]), arr)


def generate_route(house: str, seed: int, dt: float = CONTROL_DT) -> RouteScript:
    """A verified taught route in ``house`` (a map name, a path or random:SEED) for route ``seed``."""
    if seed < 0:
        raise ValueError(f"route seed must be >= 0, got {seed}")
    h = load_house(house)
    grid = grid_of(h)
    for attempt in range(ATTEMPTS):
        rng = np.random.default_rng([house_key(house), seed, attempt, 31])
        pts = plan_polyline(grid, rng)
        if pts is None or len(pts) < 2:
            continue
        yaw0, segments = polyline_segments(grid, pts, rng, dt)
        script = RouteScript(
            (round(float(pts[0][0]), 4), round(float(pts[0][1]), 4), round(yaw0, 5)),
            tuple(segments),
            route_name(house, seed),
        )
        if script.duration > MAX_DURATION:
            continue
        check = drive(h, script, dt)
        if (
            not check.touched
            and check.min_clearance >= VERIFY_CLEARANCE
            and math.dist(check.end[:2], pts[-1]) <= END_TOLERANCE
        ):
            return script
    raise RuntimeError(f"no valid route in {house} for seed {seed} after {ATTEMPTS} attempts")


_GRIDS: dict[str, ClearanceGrid] = {}


def grid_of(house: House) -> ClearanceGrid:
    """The house's clearance grid, kept for the few houses a process works on (a few MB each)."""
    if house.source not in _GRIDS:
        if len(_GRIDS) >= 4:
            _GRIDS.pop(next(iter(_GRIDS)))
        _GRIDS[house.source] = clearance_grid(house)
    return _GRIDS[house.source]


def route_json(script: RouteScript) -> dict[str, Any]:
    """The ROUTE.json dict of a script (runtime.route_script's format)."""
    x, y, yaw = script.start
    return {
        "name": script.name,
        "start": {"x": x, "y": y, "yaw": yaw},
        "segments": [{"v": s.v, "w": s.w, "duration": s.duration} for s in script.segments],
    }
