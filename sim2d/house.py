"""The house: rooms, walls, furniture and textures loaded from a JSON map (numpy only).

A map file (see sim2d/maps/house.json) holds:

- ``name``, ``wall_thickness`` (m), ``ceiling_color`` [r, g, b], ``door_texture`` (texture of door jambs),
  ``floor``: ``{"tile": m, "seed": int, "grout": [r, g, b]}`` for the mosaic;
- ``textures``: ``{name: {"kind": ..., "colors": [[r, g, b], ...], "size": [su, sv], ...}}`` (sim2d.textures);
- ``rooms``: ``[{"name", "polygon": [[x, y], ...], "walls": {"n": tex, "e": tex, "s": tex, "w": tex}}]``; rooms
  meet at wall centrelines, so together they cover the interior; a wall face takes the texture of the room
  it faces, by which side of that room it is on (so the four walls of a room differ);
- ``walls``: ``[[[x0, y0], [x1, y1]], ...]`` centrelines; each becomes a solid box ``wall_thickness`` wide,
  extended by half the thickness at both ends so corners close; doorways are gaps between walls;
- ``furniture``: ``[{"name", "shape": "box"|"polygon"|"circle", "height": m, "texture": name, ...}]`` with
  ``center``, ``size`` [sx, sy], ``angle_deg`` (box), ``points`` (convex polygon) or ``center``, ``radius``;
- ``start_poses``: ``[{"name", "x", "y", "yaw"}]``, the first being the default start.
"""

from __future__ import annotations

import functools
import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vtr.sim2d.config import Pose
from vtr.sim2d.floors import floor_image
from vtr.sim2d.house_schema import Furniture, HouseError, _points, _Validator  # noqa: F401 (re-exported)
from vtr.sim2d.lighting import Lighting
from vtr.sim2d.textures import make_texture

MAPS_DIR = Path(__file__).resolve().parent / "maps"
FLOOR_TEX = 512  # texels per side of the floor mosaic (power of two)
# Start poses are checked against a robot of this radius, the largest one we expect to simulate.
START_CLEARANCE = 0.25
RANDOM_PREFIX = "random:"  # --house random:SEED names a procedural house (sim2d.procedural)


@dataclass(frozen=True)
class Room:
    name: str
    polygon: np.ndarray  # (K, 2) float64, counter-clockwise or clockwise


@dataclass(frozen=True)
class Segments:
    """Surfaces the camera sees, as line segments in the house frame (all arrays length S)."""

    a: np.ndarray  # (S, 2) start points
    b: np.ndarray  # (S, 2) end points
    u0: np.ndarray  # (S,) texture coordinate (m) at the start point
    texture: np.ndarray  # (S,) int index into House.texture_names
    height: np.ndarray  # (S,) top of the surface (m); np.inf for walls (the camera's wall height applies)
    is_wall: np.ndarray  # (S,) bool


class House:
    """A loaded, validated house. Geometry is immutable; the pymunk space is built from it on each reset."""

    def __init__(self, data: dict[str, Any], source: str) -> None:
        self.source = source
        v = _Validator(source)
        self.name: str = v.string(data, "name")
        self.wall_thickness: float = v.number(data, "wall_thickness", lo=0.02, hi=1.0)
        self.ceiling_color = v.color(data, "ceiling_color")
        floor = v.mapping(data, "floor")
        self.floor_tile = v.number(floor, "tile", lo=0.05, hi=2.0, where="floor")
        self.floor_seed = v.integer(floor, "seed", where="floor")
        self.floor_grout = v.color(floor, "grout", where="floor")

        textures = v.mapping(data, "textures")
        if not textures:
            raise HouseError(f"{source}: textures: at least one texture is needed")
        self.texture_names: list[str] = sorted(textures)
        self.texture_images: list[np.ndarray] = []
        sizes = []
        for i, tname in enumerate(self.texture_names):
            spec = textures[tname]
            where = f"{source}: textures.{tname}"
            if not isinstance(spec, dict):
                raise HouseError(f"{where}: expected an object, got {spec!r}")
            try:
                self.texture_images.append(make_texture(spec, where, seed=1000 + i))
            except ValueError as err:
                raise HouseError(str(err)) from None
            size = spec.get("size", [1.0, 1.0])
            if (
                not isinstance(size, list)
                or len(size) != 2
                or not all(isinstance(s, (int, float)) and 0.05 <= s <= 20 for s in size)
            ):
                raise HouseError(f"{where}.size: expected [su, sv] in metres within 0.05..20, got {size!r}")
            sizes.append(size)
        self.texture_sizes = np.asarray(sizes, dtype=np.float64)  # (T, 2) metres per repeat (u, v)
        tex_index = {n: i for i, n in enumerate(self.texture_names)}
        self.door_texture = v.texture_ref(data, "door_texture", tex_index)

        self.rooms: list[Room] = []
        self._room_textures: list[dict[str, int]] = []
        for i, r in enumerate(v.list(data, "rooms", min_len=1)):
            where = f"rooms[{i}]"
            name = v.string(r, "name", where=where)
            if any(room.name == name for room in self.rooms):
                raise HouseError(f"{source}: {where}.name: duplicate room name {name!r}")
            poly = v.polygon(r, "polygon", where=where)
            walls = v.mapping(r, "walls", where=where)
            faces = {}
            for side in ("n", "e", "s", "w"):
                faces[side] = v.texture_ref(walls, side, tex_index, where=f"{where}.walls")
            self.rooms.append(Room(name, poly))
            self._room_textures.append(faces)

        self._room_boxes = [_box_of(r.polygon) for r in self.rooms]
        t = self.wall_thickness
        self.wall_boxes: list[np.ndarray] = []  # (4, 2) counter-clockwise corners of each wall box
        for i, w in enumerate(v.list(data, "walls", min_len=3)):
            pts = _points(w, f"{source}: walls[{i}]", n=2)
            a, b = pts[0], pts[1]
            length = float(np.hypot(*(b - a)))
            if length < 1e-6:
                raise HouseError(f"{source}: walls[{i}]: zero-length wall {w!r}")
            d = (b - a) / length
            nrm = np.array([-d[1], d[0]])
            a2, b2 = a - d * t / 2, b + d * t / 2
            self.wall_boxes.append(
                np.array([a2 - nrm * t / 2, b2 - nrm * t / 2, b2 + nrm * t / 2, a2 + nrm * t / 2])
            )

        self.furniture: list[Furniture] = []
        for i, f in enumerate(v.list(data, "furniture", min_len=0)):
            self.furniture.append(v.furniture(f, f"furniture[{i}]", tex_index))

        self._build_obstacles()
        all_pts = np.concatenate([r.polygon for r in self.rooms] + self.wall_boxes)
        lo, hi = all_pts.min(axis=0), all_pts.max(axis=0)
        self.bounds: tuple[float, float, float, float] = (
            float(lo[0]),
            float(lo[1]),
            float(hi[0]),
            float(hi[1]),
        )

        self.start_poses: list[Pose] = []
        self.start_names: list[str] = []
        for i, p in enumerate(v.list(data, "start_poses", min_len=1)):
            where = f"start_poses[{i}]"
            pose = Pose(
                v.number(p, "x", where=where), v.number(p, "y", where=where), v.number(p, "yaw", where=where)
            )
            if not self.is_free(pose.x, pose.y, START_CLEARANCE):
                raise HouseError(
                    f"{source}: {where}: ({pose.x}, {pose.y}) is not free space for a robot of radius "
                    f"{START_CLEARANCE} m (inside a wall or furniture, or outside every room)"
                )
            self.start_poses.append(pose)
            self.start_names.append(str(p.get("name", f"start{i}")))

        self.segments = self._build_segments(tex_index)
        # Floor mosaic: a square power-of-two texture covering the bounds (with a small margin).
        self.floor_extent = float(max(hi - lo)) + 0.2
        self.floor_origin = (float(lo[0]) - 0.1, float(lo[1]) - 0.1)
        try:
            self.lighting = Lighting.from_spec(data.get("lighting"), f"{source}: lighting")
            floor_img = floor_image(
                floor, self.floor_origin, self.floor_extent, FLOOR_TEX, f"{source}: floor"
            )
        except ValueError as err:
            raise HouseError(str(err)) from None
        self.floor_image = self.lighting.light_image(floor_img, self.floor_origin, self.floor_extent)

    # ----------------------------------------------------------------------------------------- queries
    def room_at(self, x: float, y: float) -> str | None:
        """Name of the room containing (x, y), or None outside every room."""
        # Hot path (collection asks several times per frame): a bounding-box test first; for an axis-aligned
        # rectangle it is the answer (x0 <= x < x1, y0 <= y < y1 is what the even-odd rule gives).
        for room, (x0, y0, x1, y1, is_rect) in zip(self.rooms, self._room_boxes, strict=True):
            if x0 <= x < x1 and y0 <= y < y1 and (is_rect or _inside(room.polygon, x, y)):
                return room.name
        return None

    def is_free(self, x: float, y: float, radius: float) -> bool:
        """True if a disc of `radius` at (x, y) lies inside the house and touches no wall or furniture."""
        return self.room_at(x, y) is not None and self.clearance(x, y) >= radius

    def clearance(self, x: float, y: float) -> float:
        """Distance from (x, y) to the nearest wall or furniture surface (0 inside one)."""
        a, ab, inv_len2, poly_id, n_poly, b_y = self._edges
        ap = np.array([x, y]) - a  # (E, 2)
        t = np.clip(np.einsum("ij,ij->i", ap, ab) * inv_len2, 0.0, 1.0)
        d = ap - ab * t[:, None]
        best = float(np.sqrt(np.min(d[:, 0] ** 2 + d[:, 1] ** 2)))
        # Even-odd rule per polygon: count edges crossed by a ray from (x, y) towards +x.
        straddle = (a[:, 1] > y) != (b_y > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = a[:, 0] + (y - a[:, 1]) * ab[:, 0] / ab[:, 1]
        crossings = np.bincount(poly_id, weights=straddle & (x < x_cross), minlength=n_poly)
        if np.any(crossings % 2 == 1):
            return 0.0
        centers, radii = self._circles
        if len(radii):
            best = min(best, float(np.max([0.0, np.min(np.hypot(*(centers - (x, y)).T) - radii)])))
        return best

    def clearances(self, xy: np.ndarray) -> np.ndarray:
        """clearance() of many points (N, 2) at once; 0 outside every room too (so > r means is_free)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        a, ab, inv_len2, poly_id, n_poly, b_y = self._edges
        ap = xy[:, None, :] - a[None]  # (N, E, 2)
        t = np.clip(np.einsum("nij,ij->ni", ap, ab) * inv_len2, 0.0, 1.0)
        d = ap - ab[None] * t[..., None]
        best = np.sqrt(np.min(d[..., 0] ** 2 + d[..., 1] ** 2, axis=1))
        y = xy[:, 1:2]
        straddle = (a[None, :, 1] > y) != (b_y[None] > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = a[None, :, 0] + (y - a[None, :, 1]) * ab[None, :, 0] / ab[None, :, 1]
        hits = (straddle & (xy[:, :1] < x_cross)).astype(np.int64)
        inside = np.zeros((len(xy), n_poly), dtype=np.int64)
        np.add.at(inside.T, poly_id, hits.T)
        best[np.any(inside % 2 == 1, axis=1)] = 0.0
        centers, radii = self._circles
        if len(radii):
            dc = np.hypot(xy[:, None, 0] - centers[None, :, 0], xy[:, None, 1] - centers[None, :, 1]) - radii
            best = np.minimum(best, np.maximum(dc.min(axis=1), 0.0))
        in_room = np.array([self.room_at(float(x), float(y)) is not None for x, y in xy])
        return np.where(in_room, best, 0.0)

    def _build_obstacles(self) -> None:
        """Edges of every obstacle polygon (walls, polygonal furniture) and the circles, as arrays."""
        polys = list(self.wall_boxes) + [f.vertices for f in self.furniture if f.shape != "circle"]
        a = np.concatenate(polys)
        b = np.concatenate([np.roll(p, -1, axis=0) for p in polys])
        ab = b - a
        poly_id = np.concatenate([np.full(len(p), i) for i, p in enumerate(polys)])
        # b's y as stored, not a + ab: the even-odd test must see a shared vertex at one height from both of
        # its edges (a + ab can differ by an ulp, and a ray through that vertex then counted one edge: house
        # random:5501's start pose tested as inside a wall box it was 0.8 m from)
        inv_len2 = 1.0 / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
        self._edges = (a, ab, inv_len2, poly_id, len(polys), b[:, 1].copy())
        circles = [f for f in self.furniture if f.shape == "circle"]
        self._circles = (
            np.array([f.center for f in circles], dtype=np.float64).reshape(-1, 2),
            np.array([f.radius for f in circles], dtype=np.float64),
        )

    # ----------------------------------------------------------------------------------------- building
    def _build_segments(self, tex_index: dict[str, int]) -> Segments:
        a_list, b_list, u0, tex, height, is_wall = [], [], [], [], [], []
        t = self.wall_thickness
        for wi, box in enumerate(self.wall_boxes):
            for k in range(4):
                p, q = box[k], box[(k + 1) % 4]
                length = float(np.hypot(*(q - p)))
                d = (q - p) / length
                outward = np.array([d[1], -d[0]])  # boxes are counter-clockwise: outward is to the right
                probe = (p + q) / 2 + outward * 1e-3
                if self.room_at(*probe) is None:
                    continue  # faces the outside of the house: never seen
                if any(_inside(other, *probe) for j, other in enumerate(self.wall_boxes) if j != wi):
                    continue  # buried in another wall
                deep = (p + q) / 2 + outward * 0.05
                if length <= t + 1e-6 and self.room_at(*(deep + d * 0.3)) != self.room_at(*(deep - d * 0.3)):
                    texture = self.door_texture  # a wall end between two rooms: a door jamb
                else:
                    room_i = next(i for i, r in enumerate(self.rooms) if _inside(r.polygon, *probe))
                    # A face whose outward normal points south is the room's north wall, and so on.
                    ang = math.atan2(outward[1], outward[0])
                    side = ("w", "s", "e", "n")[int(((ang + math.pi / 4) % (2 * math.pi)) // (math.pi / 2))]
                    texture = self._room_textures[room_i][side]
                a_list.append(p)
                b_list.append(q)
                # u follows a world coordinate along the face so that collinear pieces continue the pattern.
                u0.append(float(np.dot(p, np.abs(d))))
                tex.append(texture)
                height.append(np.inf)
                is_wall.append(True)
        for f in self.furniture:
            verts = f.vertices
            acc = 0.0
            for k in range(len(verts)):
                p, q = verts[k], verts[(k + 1) % len(verts)]
                a_list.append(p)
                b_list.append(q)
                u0.append(acc)
                acc += float(np.hypot(*(q - p)))
                tex.append(tex_index[f.texture])
                height.append(f.height)
                is_wall.append(False)
        return Segments(
            a=np.asarray(a_list, dtype=np.float64),
            b=np.asarray(b_list, dtype=np.float64),
            u0=np.asarray(u0, dtype=np.float64),
            texture=np.asarray(tex, dtype=np.int64),
            height=np.asarray(height, dtype=np.float64),
            is_wall=np.asarray(is_wall, dtype=bool),
        )

    def __repr__(self) -> str:
        return (
            f"House({self.name!r}, rooms={[r.name for r in self.rooms]}, walls={len(self.wall_boxes)}, "
            f"furniture={len(self.furniture)}, bounds={self.bounds})"
        )


# --------------------------------------------------------------------------------------------- loading
def resolve_house_path(name_or_path: str | os.PathLike[str]) -> Path:
    """A bare name (no separator, no suffix) means sim2d/maps/NAME.json; anything else is a path."""
    s = os.fspath(name_or_path)
    if os.sep not in s and "/" not in s and not s.endswith(".json"):
        path = MAPS_DIR / f"{s}.json"
        if not path.is_file():
            known = sorted(p.stem for p in MAPS_DIR.glob("*.json"))
            raise HouseError(f"unknown house {s!r}; known maps: {', '.join(known) or '(none)'}")
        return path
    path = Path(s)
    if not path.is_file():
        raise HouseError(f"house file not found: {path}")
    return path


def _read_json(path: str) -> dict[str, Any]:
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise HouseError(f"{path}: cannot read: {err}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise HouseError(f"{path}: invalid JSON at line {err.lineno} column {err.colno}: {err.msg}") from None
    if not isinstance(data, dict):
        raise HouseError(f"{path}: the top level must be a JSON object, got {type(data).__name__}")
    return data


def house_data(name_or_path: str | os.PathLike[str] = "house") -> tuple[dict[str, Any], str]:
    """The map of a house as a fresh JSON-like dict and its source: ``random:SEED`` (sim2d.procedural), a
    map name in sim2d/maps or a path."""
    s = os.fspath(name_or_path)
    if s.startswith(RANDOM_PREFIX):
        from vtr.sim2d.procedural import generate_house_data, parse_random_seed

        seed = parse_random_seed(s)
        return generate_house_data(seed), f"{RANDOM_PREFIX}{seed}"
    path = resolve_house_path(s)
    return _read_json(str(path)), str(path)


@functools.lru_cache(maxsize=8)
def _load_cached(name: str, mtime_ns: int, changes: tuple[str, ...]) -> House:
    data, source = house_data(name)
    if changes:
        from vtr.sim2d.appearance import apply_changes

        try:
            data = apply_changes(data, changes)
        except ValueError as err:
            raise HouseError(f"{source}: {err}") from None
        source = f"{source} with {'; '.join(changes)}"
    return House(data, source)


def load_house(name_or_path: str | os.PathLike[str] = "house", changes: tuple[str, ...] = ()) -> House:
    """Load and validate a house (cached per source, file modification time and appearance changes; Houses
    are not mutated). ``random:SEED`` generates a procedural house; `changes` are sim2d.appearance specs."""
    s = os.fspath(name_or_path)
    mtime = 0 if s.startswith(RANDOM_PREFIX) else resolve_house_path(s).stat().st_mtime_ns
    return _load_cached(s, mtime, tuple(str(c) for c in changes))


# --------------------------------------------------------------------------------------------- helpers
def _box_of(poly: np.ndarray) -> tuple[float, float, float, float, bool]:
    """(x0, y0, x1, y1, is an axis-aligned rectangle) of a room polygon."""
    (x0, y0), (x1, y1) = poly.min(axis=0), poly.max(axis=0)
    corners = {(float(x), float(y)) for x, y in poly}
    is_rect = len(poly) == 4 and corners == {(x0, y0), (x1, y0), (x1, y1), (x0, y1)}
    return float(x0), float(y0), float(x1), float(y1), bool(is_rect)


def _inside(poly: np.ndarray, x: float, y: float) -> bool:
    """Even-odd point-in-polygon test."""
    px, py = poly[:, 0], poly[:, 1]
    qx, qy = np.roll(px, -1), np.roll(py, -1)
    crosses = (py > y) != (qy > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = px + (y - py) * (qx - px) / (qy - py)
    return bool(np.count_nonzero(crosses & (x < xint)) % 2)
