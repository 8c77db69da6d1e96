"""Camera-only obstruction detection: stop as blocked when the floor the robot is about to drive over stops
matching the taught view in a region that grows while the robot moves.

Where the route localiser places the robot (position ``s`` in subgoal units), the taught view of subgoal
``k = floor(s)`` is warped by the floor plane to the taught pose at ``s`` (runtime.floor_view): the floor
then lines up as it looks from there, and what stands on it does not. Without the warp, the floor just
ahead moves by several pixels between two subgoals, as much as a box changes it, and a fast route looks
blocked half of the time. The robot is a little off that pose (a few centimetres, a few degrees), so each
tile of the view is compared with the warped view's tile shifted by up to ``shift_rows_deg`` x
``shift_cols_deg`` (angles, in pooled pixels of the robot's camera), and with the taught views of subgoals
``k`` and ``k + 1`` as they are, as the patch matcher
compares (normalised per channel, so light drops out): a tile is *unmatched* when none of them is within
``tile_threshold``. Normalised, a plain tile matches any plain tile: one plain in the view is matched only
where its colour, against the view's floor (which drops a colour cast and a light darker on one side), is
also within ``colour_threshold`` of a taught view's (a plain box face on a plain floor cell of another
colour). A robot further off (10 cm beside the path, turned 10 degrees: the floor 0.3 m ahead
moves 10 pooled pixels; or a few centimetres ahead of or behind the estimate, which moves the near floor's
rows) gets one more try, where the floor registration (runtime.side_offset, through ``update``'s ``side``)
places it, beside the taught pose and along it: the floor warped to there lines up again, what stands on
it still does not. Floor the taught view never saw from that pose (past its edge) is no evidence either way.

Only the tiles where the path ahead appears count (:meth:`ObstructionDetector.region`): the floor within
``half_width_m`` of the taught path from ``s`` on, ``near_m`` to ``far_m`` along it, as it lies from the
taught pose at ``s`` (a straight corridor on a straight route; around the corner after a turn), each tile
weighed by how much of it sees that floor. An object beside the path never covers those pixels, nor does a
repainted wall or a moved chair off the path, whichever way the camera looks. A view with too little of
the path in it (``min_region``: the path turned out of view) judges nothing. An object on the path covers
more of it the closer the robot gets, and hides the floor behind it: the detector fires only when the
unmatched share is at least ``block_fraction``, has kept growing (never dropping by more than ``slack``)
for ``grow_steps`` steps in which the robot moved (drove forward or turned: :func:`moving`), by
``min_growth`` in all, grew from a region that matched (``max_base`` or less unmatched) or came into view
unmatched (a path that turned out of view and back, as in a taught turn in place: its floor was never seen
matched; only where the floor matched before the turn), or was unmatched from the first view while the floor
beside it matched (a box already in view), and at least ``hidden_fraction`` of the region is unmatched all
the way up its column to the region's far end, while no more than ``max_elsewhere`` of the floor beside the
region is unmatched (``max_elsewhere_assumed`` where the region was never seen matched: then the floor beside
it is the only witness that something stands on the path rather than the floor changed; judged on taught
tiles with texture that the floor plane explains,
:meth:`ObstructionDetector.floor_evidence`: walls and furniture stay when a floor is re-laid, and would water
its share down; pooled over the views of the unmatched spell, obstruction_decision.Growth). A floor that
looks different everywhere (a new carpet), a robot off its pose (which mismatches the floor nearest to it
first), or a region that is unmatched while the robot stands, does not fire. Things lower than about two
thirds of the camera's height hide too little of the far floor to be seen this way (the range sensor's job).
Once blocked, the verdict holds until the region matches again (``clear_fraction`` or less for
``clear_steps`` views): the caller waits on it and resumes when it clears. It also clears when the floor at
the region's far end is seen again (``clear_hidden`` or less unmatched all the way up): a robot that stopped
a little off its pose still mismatches some floor near it once the box is gone.

Use: ``ObstructionDetector(route.images, route.travel_poses())``, then per view ``update(image,
estimate.position, moved)`` with ``moved`` true when the robot was commanded to move since the last view.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from vtr.runtime.floor_view import (
    Camera,
    FloorTiles,
    Offset,
    near_path,
    path_ahead,
    path_weights,
    relative_pose,
    taught_offset,
    tile_floor_points,
)
from vtr.runtime.frame import Frame, as_frame
from vtr.runtime.matching import MatchConfig, Matcher, pooled_sums
from vtr.runtime.obstruction_decision import Growth, ObstructionConfig, ObstructionVerdict, once

#: Commands faster than this (m/s) count as driving forward, or turning faster than this (rad/s) as turning:
#: either moves the robot (``update``'s ``moved``).
FORWARD_SPEED, TURN_SPEED = 0.02, 0.05


#: A path ahead that strays less than this (m) from the camera's axis is the straight corridor.
STRAIGHT_M = 0.005

#: The least travel (m) between two taught views for the floor plane to tell floor from what stands up: a
#: wall or a cupboard moves across the view differently from the floor it hides only over a baseline.
FLOOR_BASE_M = 0.1


def moving(v: float, w: float) -> bool:
    """Whether the command (v, w) moves the robot: driving forward, or turning (in place or on an arc)."""
    return v > FORWARD_SPEED or abs(w) > TURN_SPEED


#: Where the floor puts the robot against the taught pose at the estimate: ``(dy, psi, dx)`` (m to the left,
#: rad turned left, m ahead along the route; ``runtime.side_offset.SideEstimate``), or None.
SideFn = Callable[[], "tuple[float, float, float] | None"]


def beside(offset: Offset, dy: float, psi: float, dx: float = 0.0) -> Offset:
    """The pose ``dx`` ahead of, ``dy`` to the left of and turned ``psi`` from the taught pose at ``offset``
    (relative to a taught view), relative to that view."""
    ahead, left, turn = offset
    c, s = math.cos(turn), math.sin(turn)
    return ahead + c * dx - s * dy, left + s * dx + c * dy, turn + psi


class ObstructionDetector:
    """The unmatched share of the path region, view by view, and the growth decision on it.

    ``subgoals``: the route's (L, H, W, 3) uint8 taught views; ``poses``: their (L, 3) taught poses (x, y,
    yaw; the route's travel poses), None or NaN where unknown (no warp then, and the path region is the
    straight corridor ahead)."""

    def __init__(
        self,
        subgoals: np.ndarray,
        poses: np.ndarray | None = None,
        cfg: ObstructionConfig | None = None,
        camera: Camera | None = None,
    ) -> None:
        if subgoals.dtype != np.uint8 or subgoals.ndim != 4 or subgoals.shape[-1] != 3 or not len(subgoals):
            raise ValueError(f"subgoals must be (L, H, W, 3) uint8, got {subgoals.shape} {subgoals.dtype}")
        self.cfg = cfg = cfg or ObstructionConfig()
        self.matcher = Matcher(MatchConfig(std_floor=cfg.std_floor))
        h, w = subgoals.shape[1:3]
        base = camera or Camera()
        camera = Camera(h, w, base.fov_deg, base.height_m)
        tile = self.matcher.cfg.downsample * self.matcher.cfg.patch
        # every tile that sees floor near_m to far_m ahead: the path region is some of them in each view
        tiles = np.flatnonzero(path_weights(camera, tile, 1e3, cfg.near_m, cfg.far_m))
        straight = path_weights(camera, tile, cfg.half_width_m, cfg.near_m, cfg.far_m)[tiles]
        if not straight.any():
            raise ValueError(f"no tile of a {h}x{w} image sees the path region")
        self._straight_raw = straight.astype(np.float32)
        self._straight = (straight / straight.sum()).astype(np.float32)

        self._least = cfg.min_region * float(straight.sum())
        self._points = tile_floor_points(camera, tile, tiles, 3).reshape(-1, 2)
        shifts = cfg.pooled_shifts(camera.focal_px / self.matcher.cfg.downsample)
        self.floor = FloorTiles(camera, tiles, self.matcher, *shifts)
        per_row = w // tile
        row, col = tiles // per_row, tiles % per_row
        # [i, j]: 1 where tile j is further along tile i's column (it sees the floor behind i's)
        self._beyond = ((col[None, :] == col[:, None]) & (row[None, :] < row[:, None])).astype(np.float32)
        self.subgoals = subgoals
        self.poses = None if poses is None else np.asarray(poses, dtype=np.float64)
        if self.poses is not None and not np.isfinite(self.poses).all():
            self.poses = None
        # (L, tiles) the path region seen from each subgoal, unnormalised
        self._regions = (
            None
            if self.poses is None
            else np.stack([self._floor_ahead(float(k)) for k in range(len(self.poses))])
        )
        #: The path region's weight per tile (``floor.tiles``) in the last view judged.
        self.weights = self._straight
        feats, colours = [], []
        for image in subgoals:
            band = self.floor.pool(image)
            feats.append(self.floor.features(band))
            colours.append(self.floor.colours(band))
        self._feats = np.stack(feats)
        self._colours = np.stack(colours)  # (L, tiles, 3): each taught tile's colour (FloorTiles.colours)
        self._bands: dict[int, np.ndarray] = {}  # pooled taught bands of the last few subgoals
        self._evidence: dict[int, np.ndarray] = {}  # floor_evidence per subgoal, made when first asked
        self.growth = Growth(cfg)
        self._unseen = np.zeros(len(tiles), dtype=bool)  # the tiles of the last view the teach never saw
        self._side: SideFn | None = None  # the side offset of the view being judged (update's ``side``)

    def floor_evidence(self, k: int) -> np.ndarray:
        """(tiles,) whether each tile of taught view ``k`` can show the floor changed: it has texture (a plain
        patch matches any plain patch by texture, and only its colour could tell a change, but the floor-plane
        check below cannot tell a plain floor from a plain wall) and it is floor, not a wall or furniture
        (which a re-laid floor leaves as they were): every taught view ``FLOOR_BASE_M`` to two subgoals away,
        warped by the floor plane to view ``k``, matches it where it saw it (what stands up moves across the
        view otherwise). Without taught poses, or no such view near, every textured tile. Made when first
        asked (only a growth about to block asks), then kept."""
        known = self._evidence.get(k)
        if known is not None:
            return known
        cfg, floor = self.cfg, self.floor
        evidence = np.abs(self._feats[k]).mean(axis=-1) > cfg.tile_threshold / 2
        for j in (k - 2, k - 1, k + 1, k + 2):
            if self.poses is None or not 0 <= j < len(self.poses):
                continue
            at = relative_pose(self.poses[j], self.poses[k])
            if math.hypot(at[0], at[1]) >= FLOOR_BASE_M:
                warped = floor.features(floor.warp(floor.pool(self.subgoals[j]), at))
                d = self.matcher.tile_distances(self._feats[k], warped)[0]
                evidence &= (d <= cfg.tile_threshold) | ~floor.seen(at)
        self._evidence[k] = evidence
        return evidence

    def reset(self) -> None:
        """Forget the tracked region (a new run, or the robot moved elsewhere)."""
        self.growth.reset()

    @property
    def blocked(self) -> bool:
        return self.growth.blocked

    def _floor_ahead(self, position: float) -> np.ndarray:
        """(tiles,) the share of each tile that sees the taught path ahead of ``position`` (unnormalised)."""
        cfg = self.cfg
        assert self.poses is not None
        path = path_ahead(self.poses, position, cfg.far_m + cfg.half_width_m)
        straight = np.abs(path[:, 1]).max() < STRAIGHT_M
        if straight and path[-1, 0] >= cfg.far_m + cfg.half_width_m - STRAIGHT_M:
            return self._straight_raw  # straight on for the whole region (most views): the corridor ahead
        inside = near_path(self._points, path, cfg.half_width_m, cfg.near_m, cfg.far_m)
        return inside.reshape(len(self.floor.tiles), -1).mean(axis=1).astype(np.float32)

    def region(self, position: float) -> np.ndarray:
        """(tiles,) the share of each tile that sees the floor the robot is about to drive over: the taught
        path from ``position`` on, ``half_width_m`` to each side, ``near_m`` to ``far_m`` along it, as it
        lies from the taught pose there (the straight corridor ahead without taught poses); normalised,
        all zero where less than ``min_region`` of a straight path's floor is in view. Between subgoals,
        the blend of the regions seen from the two (each computed once, when the route is loaded)."""
        if self._regions is None:
            return self._straight
        k = max(0, min(int(math.floor(position)), len(self.poses) - 1))
        t = min(max(position - k, 0.0), 1.0) if k + 1 < len(self.poses) else 0.0
        weights = self._regions[k] if t == 0.0 else (1 - t) * self._regions[k] + t * self._regions[k + 1]
        total = float(weights.sum())
        return weights / total if total >= self._least else np.zeros_like(weights)

    def scores(self, view: Frame | np.ndarray, position: float, exhaustive: bool = False) -> np.ndarray:
        """Each path-region tile's distance to the taught views where the robot is (0 for the tiles of
        ``floor.tiles`` outside the region, :meth:`region`, kept in ``weights``): ``view``, a frame (or a
        (H, W, 3) uint8 image); ``position``: the localiser's estimate, in subgoal units. The taught views
        are tried cheapest first (subgoals ``k`` and ``k + 1`` as they are, then ``k`` warped, then its
        shifts), each only for the tiles none before matched, so a matched tile's score is under
        ``tile_threshold`` but not always its least; ``exhaustive``: the least distance of every tile (for
        studies)."""
        view = as_frame(view, self.subgoals.shape[1:3])  # a frame as it is; an array checked here, once
        self.weights = self.region(position)
        return self._distances(view, position, np.flatnonzero(self.weights), exhaustive)

    def elsewhere(self, view: Frame | np.ndarray, position: float) -> float:
        """:meth:`beside_tiles` as a share (0 where none is judged)."""
        unmatched, judged = self.beside_tiles(view, position)
        return unmatched / judged if judged else 0.0

    def beside_tiles(self, view: Frame | np.ndarray, position: float) -> tuple[int, int]:
        """The unmatched and judged tiles of the floor beside the path region of the last view scored: its
        tiles the taught view shows as floor (:meth:`floor_evidence`) and saw from where the robot is. Walls
        and furniture never change with the floor, and would water a re-laid floor's share down."""
        view = as_frame(view, self.subgoals.shape[1:3])
        k = taught_offset(self.poses, position)[0]
        outside = np.flatnonzero((self.weights == 0) & self.floor_evidence(k))
        if not len(outside):
            return 0, 0
        d = self._distances(view, position, outside)
        judged = outside[~self._unseen[outside]]
        return int(np.count_nonzero(d[judged] > self.cfg.tile_threshold)), len(judged)

    def _distances(
        self, view: Frame, position: float, active: np.ndarray, exhaustive: bool = False
    ) -> np.ndarray:
        """:meth:`scores` for the tiles ``active`` (indices into ``floor.tiles``), 0 for the others: the
        texture's distance (:meth:`_texture`), and where a plain tile of the view matched by texture, its
        colour (:meth:`_colour`)."""
        tried: list[np.ndarray] = []
        d = self._texture(view, position, active, exhaustive, tried)
        if len(active):
            self._colour(view, position, active, d, tried)
        return d

    def _band(self, k: int) -> np.ndarray:
        """Taught view ``k``'s pooled band (the last few kept)."""
        band = self._bands.get(k)
        if band is None:
            if len(self._bands) >= 4:
                self._bands.clear()
            band = self._bands[k] = self.floor.pool(self.subgoals[k])
        return band

    def _colour(
        self, view: Frame, position: float, active: np.ndarray, d: np.ndarray, tried: list[np.ndarray]
    ) -> None:
        """Unmatch, in ``d``, the tiles of ``active`` that are plain in the view (every channel's spread under
        the matcher's floor), matched by texture, and whose colour (:meth:`FloorTiles.colours`) is within
        ``colour_threshold`` of no taught view they were compared with (subgoals ``k`` and ``k + 1`` as they
        are, and the warped bands ``tried``, each shifted; the taught pose's warp when none was). A plain patch
        matches any plain patch once normalised: a plain box face stood on a plain floor cell of another
        colour matched it (dev gen_107: half the box's tiles, the stop 0.30 m from it and then a false
        clear)."""
        cfg, floor = self.cfg, self.floor
        ds = self.matcher.cfg.downsample
        spread = self.matcher.moments(view)[1][floor.tiles[active]].reshape(len(active), -1)
        plain = (spread < self.matcher.cfg.std_floor * ds * ds).all(axis=1)
        which = active[plain & (d[active] <= cfg.tile_threshold) & ~self._unseen[active]]
        if not len(which):
            return
        own = floor.colours(pooled_sums(view, ds)[:, floor.top :], which)  # the frame's shared sums: (n, 3)
        k, offset = taught_offset(self.poses, position)
        nearest = np.abs(self._colours[k : k + 2, which] - own).sum(axis=-1).min(axis=0)
        for i in range(max(len(tried), 1)):  # the warps only for the tiles the views as they are miss
            todo = np.flatnonzero(nearest > cfg.colour_threshold)
            if not len(todo):
                break
            band = tried[i] if tried else floor.warp(self._band(k), offset)
            warped = floor.colours(band, which[todo], shifted=True)
            nearest[todo] = np.minimum(nearest[todo], np.abs(warped - own[todo]).sum(axis=-1).min(axis=0))
        off = nearest > cfg.colour_threshold
        # unmatched, by as much more than the threshold as the colour is off
        d[which[off]] = cfg.tile_threshold * nearest[off] / cfg.colour_threshold

    def _texture(
        self, view: Frame, position: float, active: np.ndarray, exhaustive: bool, tried: list[np.ndarray]
    ) -> np.ndarray:
        """Each tile's texture distance (the patch features'), for the tiles ``active``, 0 for the others; the
        warped bands of taught view ``k`` it compared with are appended to ``tried``."""
        floor, thr = self.floor, -1.0 if exhaustive else self.cfg.tile_threshold
        d = np.zeros(len(floor.tiles), dtype=np.float32)
        self._unseen = np.zeros(len(floor.tiles), dtype=bool)  # tiles the teach never saw from there
        if not len(active):
            return d
        own = floor.frame_features(view, active)  # the localiser's tile moments of this frame, shared
        k, offset = taught_offset(self.poses, position)
        d[active] = self.matcher.tile_distances(own, self._feats[k : k + 2, active]).min(axis=0)
        todo = np.flatnonzero(d[active] > thr)  # positions in active
        if not len(todo):
            return d
        band = self._band(k)
        warps = [offset]
        side = self._side() if self._side is not None else None
        if side is not None:  # where the floor puts the robot, beside and along: the floor from there
            warps.append(beside(offset, *side))
        best_known = warps[-1]
        # the localiser places the robot up to a subgoal or two off along the route: the floor from there
        ahead, left, turn = best_known
        c, s = math.cos(turn), math.sin(turn)
        warps += [(ahead + c * d, left + s * d, turn) for d in (self.cfg.along_m, -self.cfg.along_m) if d]
        for at in warps:
            warped = floor.warp(band, at)
            tried.append(warped)
            for shifted in (False, True):
                views = floor.features(warped, active[todo], shifted)
                best = self.matcher.tile_distances(own[todo], views).min(axis=0)
                d[active[todo]] = np.minimum(d[active[todo]], best)
                todo = todo[d[active[todo]] > thr]
                if not len(todo):
                    return d
        # floor the teach never saw from there (past the taught view's edge) tells nothing: not unmatched
        unseen = active[todo[~floor.seen(best_known)[active[todo]]]]
        d[unseen], self._unseen[unseen] = 0.0, True
        return d

    def shares(self, scores: np.ndarray) -> tuple[float, float]:
        """The unmatched share of the path region, and the share unmatched all the way up its column to
        its far end, from the tiles' :meth:`scores` (in the region of the last view scored)."""
        inside = (self.weights > 0).astype(np.float32)
        unmatched = (scores > self.cfg.tile_threshold).astype(np.float32) * inside
        matched_beyond = self._beyond @ (inside - unmatched)  # per tile: matched region tiles behind it
        return float(self.weights @ unmatched), float(self.weights @ (unmatched * (matched_beyond == 0)))

    def share(self, view: np.ndarray, position: float) -> float:
        """The unmatched share of the path region in one view (no tracking)."""
        return self.shares(self.scores(view, position))[0]

    def update(
        self, view: np.ndarray, position: float, moved: bool, side: SideFn | None = None
    ) -> ObstructionVerdict:
        """Judge one view (see :meth:`scores`); ``moved``: the robot was commanded to move (forward or
        turning, :func:`moving`) since the last view; ``side``: where the floor puts the robot against the
        taught pose at ``position`` (``(dy, psi, dx)``: metres to the left, radians turned left, metres
        ahead; None where it does not tell), asked once, only when some tiles match no taught view at the
        taught pose: the taught floor warped to that pose too lines up with the floor where the robot truly
        is (a robot 10 cm beside the path sees the floor 0.3 m ahead 10 pooled pixels across, past the
        shifts)."""
        self._side = once(side) if side is not None else None
        try:
            share, hidden = self.shares(self.scores(view, position))
            if not self.weights.any():
                self.growth.unseen()
                if not self.growth.blocked:  # no region in view is no matched view of it
                    return ObstructionVerdict(False, 0.0, 0, "path region out of view")
            return self.growth.update(share, hidden, moved, lambda: self.beside_tiles(view, position))
        finally:
            self._side = None


__all__ = [
    "FORWARD_SPEED",
    "TURN_SPEED",
    "SideFn",
    "Growth",
    "ObstructionConfig",
    "ObstructionDetector",
    "ObstructionVerdict",
    "beside",
    "moving",
]
