"""Path planning in a house for the route generator (sim2d.route_gen): a clearance grid, a shortest-path
search that keeps to open floor, and a line-of-sight shortcut of the found path into a polyline.

Numpy and the standard library only. The grid stores, per cell centre, the distance to the nearest wall
or piece of furniture (``House.clearances``: exact geometry, 0 outside the rooms) and the room it lies in.
Clearance is 1-Lipschitz, so between cell centres it is at least the stored value minus half a cell
diagonal; the route generator's margin is larger than that, and it verifies the final drive on the true
geometry anyway.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from vtr.sim2d.house import House

GRID = 0.05  # m between cell centres
#: Clearance beyond which open floor costs nothing extra: the search prefers to stay this far from things.
PREFERRED_CLEARANCE = 0.6
#: Extra cost per metre at zero clearance (linear down to none at PREFERRED_CLEARANCE).
CLEARANCE_COST = 3.0
_NEIGHBOURS = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0)]


@dataclass(frozen=True)
class ClearanceGrid:
    """Clearance (m) and room index per cell; cell (r, c) has centre (x0 + c * res, y0 + r * res)."""

    x0: float
    y0: float
    res: float
    clear: np.ndarray  # (H, W) float64, 0 outside the house
    room: np.ndarray  # (H, W) int, index into room_names, -1 outside
    room_names: tuple[str, ...]

    def cell(self, x: float, y: float) -> tuple[int, int]:
        """The cell nearest to (x, y), clipped to the grid."""
        r = min(max(int(round((y - self.y0) / self.res)), 0), self.clear.shape[0] - 1)
        c = min(max(int(round((x - self.x0) / self.res)), 0), self.clear.shape[1] - 1)
        return r, c

    def xy(self, r: int, c: int) -> tuple[float, float]:
        return (self.x0 + c * self.res, self.y0 + r * self.res)

    def clearance_at(self, pts: np.ndarray) -> np.ndarray:
        """Clearance of the nearest cell of each point (N, 2)."""
        pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        h, w = self.clear.shape
        c = np.clip(np.rint((pts[:, 0] - self.x0) / self.res).astype(int), 0, w - 1)
        r = np.clip(np.rint((pts[:, 1] - self.y0) / self.res).astype(int), 0, h - 1)
        return self.clear[r, c]


def clearance_grid(house: House, res: float = GRID, chunk: int = 2048) -> ClearanceGrid:
    """The clearance grid of a house (exact distances at cell centres, computed in chunks for memory)."""
    bx0, by0, bx1, by1 = house.bounds
    xs = np.arange(bx0 + res / 2, bx1, res)
    ys = np.arange(by0 + res / 2, by1, res)
    px, py = np.meshgrid(xs, ys, indexing="xy")
    pts = np.stack([px.ravel(), py.ravel()], axis=1)
    clear = np.concatenate([house.clearances(pts[i : i + chunk]) for i in range(0, len(pts), chunk)])
    names = tuple(r.name for r in house.rooms)
    index = {n: i for i, n in enumerate(names)}
    rooms = np.array([index.get(house.room_at(float(x), float(y)) or "", -1) for x, y in pts])
    shape = px.shape
    return ClearanceGrid(float(xs[0]), float(ys[0]), res, clear.reshape(shape), rooms.reshape(shape), names)


@dataclass
class SearchTree:
    """Shortest paths from one start cell: cost, driven length and room changes to every reached cell."""

    start: tuple[int, int]
    cost: np.ndarray  # (H, W) weighted cost, inf where unreached
    length: np.ndarray  # (H, W) metres along the path
    room_changes: np.ndarray  # (H, W) how often the path crosses from one room into another
    parent: np.ndarray  # (H, W) flat index of the previous cell, -1 at the start / unreached

    def path(self, goal: tuple[int, int]) -> list[tuple[int, int]]:
        """Cells from the start to ``goal`` (which must have been reached)."""
        w = self.cost.shape[1]
        out = [goal]
        k = self.parent[goal]
        while k >= 0:
            out.append((int(k // w), int(k % w)))
            k = self.parent[out[-1]]
        return out[::-1]


def search(
    grid: ClearanceGrid, start: tuple[int, int], min_clearance: float, max_length: float
) -> SearchTree:
    """Dijkstra over the 8-connected cells with clearance >= ``min_clearance``, out to ``max_length`` metres.

    Each move costs its length times 1 + CLEARANCE_COST * (shortfall below PREFERRED_CLEARANCE), so paths
    run down the middle of corridors and doorways rather than grazing furniture."""
    h, w = grid.clear.shape
    free = grid.clear >= min_clearance
    penalty = 1.0 + CLEARANCE_COST * np.clip(PREFERRED_CLEARANCE - grid.clear, 0.0, None)
    cost = np.full((h, w), np.inf)
    length = np.full((h, w), np.inf)
    changes = np.zeros((h, w), dtype=np.int64)
    parent = np.full((h, w), -1, dtype=np.int64)
    cost[start], length[start] = 0.0, 0.0
    heap = [(0.0, start[0], start[1])]
    done = np.zeros((h, w), dtype=bool)
    while heap:
        d, r, c = heapq.heappop(heap)
        if done[r, c]:
            continue
        done[r, c] = True
        for dr, dc in _NEIGHBOURS:
            rr, cc = r + dr, c + dc
            if not (0 <= rr < h and 0 <= cc < w) or done[rr, cc] or not free[rr, cc]:
                continue
            step = grid.res * (math.sqrt(2.0) if dr and dc else 1.0)
            if length[r, c] + step > max_length:
                continue
            nd = d + step * 0.5 * (penalty[r, c] + penalty[rr, cc])
            if nd < cost[rr, cc]:
                cost[rr, cc] = nd
                length[rr, cc] = length[r, c] + step
                room_a, room_b = grid.room[r, c], grid.room[rr, cc]
                changes[rr, cc] = changes[r, c] + int(room_a != room_b and room_b >= 0)
                parent[rr, cc] = r * w + c
                heapq.heappush(heap, (nd, rr, cc))
    return SearchTree(start, cost, length, changes, parent)


def line_clearance(grid: ClearanceGrid, a: np.ndarray, b: np.ndarray, step: float = 0.02) -> float:
    """The smallest grid clearance along the segment a-b, sampled every ``step`` metres."""
    n = max(2, int(math.ceil(float(np.hypot(*(b - a))) / step)) + 1)
    t = np.linspace(0.0, 1.0, n)[:, None]
    return float(grid.clearance_at(a + t * (b - a)).min())


def shortcut(grid: ClearanceGrid, cells: list[tuple[int, int]], floor: float, wanted: float) -> np.ndarray:
    """Polyline (K, 2) through the path's cells: from each vertex, jump to the farthest later cell in sight.

    "In sight" means the straight line keeps ``min(wanted, what the path had there)`` clearance (and at
    least ``floor``): a shortcut never passes closer to things than the searched path did."""
    pts = np.array([grid.xy(r, c) for r, c in cells], dtype=np.float64)
    along = grid.clearance_at(pts)
    out = [pts[0]]
    i = 0
    while i < len(pts) - 1:
        j = len(pts) - 1
        while j > i + 1:
            need = max(floor, min(wanted, float(along[i : j + 1].min())))
            if line_clearance(grid, pts[i], pts[j]) >= need - 1e-9:
                break
            j -= 1
        out.append(pts[j])
        i = j
    return np.asarray(out)


def simplify(
    grid: ClearanceGrid, pts: np.ndarray, floor: float, min_leg: float = 0.35, min_turn: float = 0.15
) -> np.ndarray:
    """Drop vertices that make a leg shorter than ``min_leg`` m or turn less than ``min_turn`` rad, where
    the line that skips them keeps ``floor`` clearance: fewer, longer legs, as a person would drive."""
    out = [p for p in pts]
    changed = True
    while changed and len(out) > 2:
        changed = False
        for j in range(1, len(out) - 1):
            a, b, c = out[j - 1], out[j], out[j + 1]
            ab, bc = b - a, c - b
            turn = abs(math.atan2(ab[0] * bc[1] - ab[1] * bc[0], float(np.dot(ab, bc))))
            short = min(float(np.hypot(*ab)), float(np.hypot(*bc))) < min_leg
            if (short or turn < min_turn) and line_clearance(grid, a, c) >= floor:
                del out[j]
                changed = True
                break
    return np.asarray(out)
