"""Camera-only obstruction detection: stop as blocked when the floor the robot is about to drive over stops
matching the taught view in a region that grows while the robot moves.

Where the route localiser places the robot (position ``s`` in subgoal units), the taught view of subgoal
``k = floor(s)`` is warped by the floor plane to the taught pose at ``s`` (runtime.floor_view): the floor
then lines up as it looks from there, and what stands on it does not. Without the warp, the floor just
ahead moves by several pixels between two subgoals, as much as a box changes it, and a fast route looks
blocked half of the time. The robot is a little off that pose (a few centimetres, a few degrees), so each
tile of the view is compared with the warped view's tile shifted by up to ``shift_rows`` x ``shift_cols``
pooled pixels, and with the taught views of subgoals ``k`` and ``k + 1`` as they are, as the patch matcher
compares (normalised per channel, so light drops out): a tile is *unmatched* when none of them is within
``tile_threshold``.

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
matched), and at least ``hidden_fraction`` of the region is unmatched all the way up its column to the
region's far end, while no more than ``max_elsewhere`` of the floor beside the region is unmatched. A floor
that looks different everywhere (a new carpet), a robot off its pose (which mismatches the floor nearest to
it first), or a region that is unmatched while the robot stands, does not fire. Things lower than about two thirds of the camera's height hide too little of the far floor to be
seen this way (the range sensor's job). Once blocked, the verdict holds until the region matches again
(``clear_fraction`` or less for ``clear_steps`` views): the caller waits on it and resumes when it clears.
It also clears when the floor at the region's far end is seen again (``clear_hidden`` or less unmatched
all the way up): a robot that stopped a little off its pose still mismatches some floor near it once the
box is gone.

Use: ``ObstructionDetector(route.images, route.travel_poses())``, then per view ``update(image,
estimate.position, moved)`` with ``moved`` true when the robot was commanded to move since the last view.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from vtr.runtime.floor_view import (
    Camera,
    FloorTiles,
    near_path,
    path_ahead,
    path_weights,
    taught_offset,
    tile_floor_points,
)
from vtr.runtime.frame import Frame, as_frame
from vtr.runtime.matching import MatchConfig, Matcher

#: Commands faster than this (m/s) count as driving forward, or turning faster than this (rad/s) as turning:
#: either moves the robot (``update``'s ``moved``).
FORWARD_SPEED, TURN_SPEED = 0.02, 0.05


#: A path ahead that strays less than this (m) from the camera's axis is the straight corridor.
STRAIGHT_M = 0.005


def moving(v: float, w: float) -> bool:
    """Whether the command (v, w) moves the robot: driving forward, or turning (in place or on an arc)."""
    return v > FORWARD_SPEED or abs(w) > TURN_SPEED


@dataclass(frozen=True)
class ObstructionConfig:
    """The detector's settings; chosen on development routes only (evaluation/README.md)."""

    #: A tile's distance (matcher units: 0 same, ~1.13 unrelated textures) above which it is unmatched.
    tile_threshold: float = 0.55
    #: The matcher's floor on a tile's spread (0..255 units), higher than for localising: a plain patch of
    #: floor under a light that changes across it (one side darker) must stay plain.
    std_floor: float = 8.0
    #: Pooled pixels (2 image pixels each) the warped taught view is shifted by, each way, down and across.
    shift_rows: int = 1
    shift_cols: int = 2
    #: The path region: half the corridor's width and its near and far ends ahead of the camera (m).
    half_width_m: float = 0.2
    near_m: float = 0.3
    far_m: float = 1.5
    #: The least floor of the path in view, as a share of what a straight path shows, for a view to count:
    #: a path turning out of view (a taught turn in place ahead) leaves a few tiles, too few to judge by.
    min_region: float = 0.3
    #: Unmatched share of the path region from which a growth is tracked, and at which it blocks.
    onset_fraction: float = 0.1
    block_fraction: float = 0.3
    #: Forward steps the share must have grown over (each no more than ``slack`` below the one before), by
    #: how much in all, and the most it may have been when the growth began.
    grow_steps: int = 3
    min_growth: float = 0.1
    slack: float = 0.05
    max_base: float = 0.25
    #: The least share of the region that must be unmatched all the way up its column to the corridor's far
    #: end: what stands on the path hides the floor behind it, where a robot off its pose mismatches the
    #: floor nearest to it first.
    hidden_fraction: float = 0.2
    #: Once blocked: the share at or under which the way counts as clear, for this many views in a row ...
    clear_fraction: float = 0.1
    clear_steps: int = 2
    #: ... or the share unmatched up to the far end at or under which it does: the floor behind where the
    #: box stood is seen again (dev route 104: taken away, 13-23% stayed unmatched near a robot stopped a
    #: little off its pose, 3% up to the far end, against 30% while the box stood there; dev route 175:
    #: 5.0-5.3% for 4 s, 21% near the robot, against 31-39% with the box: half of ``hidden_fraction``).
    clear_hidden: float = 0.1
    #: The most of the floor beside the path region (the rest of the floor ``near_m`` to ``far_m`` ahead)
    #: that may be unmatched when a growth blocks: where the floor beside the path does not match either (a
    #: re-laid or re-coloured floor; a robot far off its pose), what changed is the floor or the pose, not
    #: something on the path (held-out set 11 with the floor re-coloured blocked 36 runs of 40 without it;
    #: dev boxes on the path blocked with 11-17% unmatched beside it).
    max_elsewhere: float = 0.5

    def __post_init__(self) -> None:
        for name in ("tile_threshold", "std_floor", "half_width_m", "near_m", "far_m"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"ObstructionConfig.{name} must be a finite number > 0, got {value!r}")
        if self.far_m <= self.near_m:
            raise ValueError(f"ObstructionConfig.far_m ({self.far_m}) must exceed near_m ({self.near_m})")
        fractions = ("onset_fraction", "block_fraction", "min_growth", "slack", "max_base", "hidden_fraction")
        fractions += ("min_region",)
        for name in (*fractions, "clear_fraction", "clear_hidden", "max_elsewhere"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 <= value <= 1.0):
                raise ValueError(f"ObstructionConfig.{name} must be in [0, 1], got {value!r}")
        if not 0 < self.block_fraction or self.onset_fraction > self.block_fraction:
            raise ValueError(
                f"ObstructionConfig: need 0 < block_fraction and onset_fraction <= block_fraction, got "
                f"{self.onset_fraction}, {self.block_fraction}"
            )
        if self.clear_fraction >= self.block_fraction:
            raise ValueError(
                f"ObstructionConfig.clear_fraction ({self.clear_fraction}) must be under block_fraction "
                f"({self.block_fraction})"
            )
        if self.clear_hidden >= self.hidden_fraction:
            raise ValueError(
                f"ObstructionConfig.clear_hidden ({self.clear_hidden}) must be under hidden_fraction "
                f"({self.hidden_fraction})"
            )
        for name, least in (("grow_steps", 1), ("clear_steps", 1), ("shift_rows", 0), ("shift_cols", 0)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < least:
                raise ValueError(f"ObstructionConfig.{name} must be an integer >= {least}, got {value!r}")


@dataclass(frozen=True)
class ObstructionVerdict:
    """The detector's answer on one view: ``fraction``, the unmatched share of the path region (0..1);
    ``growing_steps``, the moving steps it has grown over; ``note``, the evidence in words; ``hidden``,
    the share unmatched all the way up its column to the corridor's far end."""

    blocked: bool
    fraction: float
    growing_steps: int
    note: str
    hidden: float = 0.0  # the share unmatched all the way to the corridor's far end


class Growth:
    """Folds each view's unmatched share into the decision (see the module docstring)."""

    def __init__(self, cfg: ObstructionConfig) -> None:
        self.cfg = cfg
        self.reset()

    def reset(self) -> None:
        self.last = 0.0  # the share on the last step the robot moved
        self.base = 0.0  # the least share since the growth began (its start)
        self.low = 0.0  # the least share since the region last matched (the unmatched spell's start)
        self.growing = 0  # moving steps since then without a drop of more than slack
        self.blocked = False
        self.clear = 0
        self.fresh = False  # the path came into view unmatched: no matched view of it to grow from

    def unseen(self) -> None:
        """No floor of the path in view (it turns out of view): the next region seen is new."""
        if not self.blocked:
            self.growing, self.last, self.low, self.fresh = 0, 0.0, 1.0, True

    def update(
        self, share: float, hidden: float, moved: bool, elsewhere: Callable[[], float] | None = None
    ) -> ObstructionVerdict:
        """Fold one view's unmatched share and hidden share in: the verdict. ``elsewhere``: the unmatched
        share of the floor beside the path region, asked only when everything else says blocked."""
        cfg = self.cfg
        if self.blocked:
            clear = share <= cfg.clear_fraction or hidden <= cfg.clear_hidden
            self.clear = self.clear + 1 if clear else 0
            if self.clear >= cfg.clear_steps:
                self.reset()
                note = f"way clear: path region {share:.0%} unmatched, {hidden:.0%} up to its far end"
                return ObstructionVerdict(False, share, 0, note, hidden)
            return ObstructionVerdict(True, share, self.growing, self.note(share), hidden)
        if share < cfg.onset_fraction:
            self.growing, self.low, self.fresh = 0, share, False
        elif moved:
            if not self.growing:
                self.base = share
            elif share < self.last - cfg.slack:  # shrank: count the growth again from here
                self.growing = 0
            self.base, self.low = min(self.base, share), min(self.low, share)
            self.growing += 1
        if moved or share < cfg.onset_fraction:
            self.last = share
        self.blocked = (
            share >= cfg.block_fraction
            and self.growing >= cfg.grow_steps
            and share - self.base >= cfg.min_growth
            and (self.low <= cfg.max_base or self.fresh)
            and hidden >= cfg.hidden_fraction
        )
        if self.blocked and elsewhere is not None and elsewhere() > cfg.max_elsewhere:
            self.blocked = False  # the floor beside the path changed as much: not evidence of something on it
        note = self.note(share) if self.blocked else f"path region {share:.0%} unmatched"
        return ObstructionVerdict(self.blocked, share, self.growing, note, hidden)

    def note(self, share: float) -> str:
        return (
            f"view ahead blocked: {share:.0%} of the path region unmatched, growing for {self.growing} steps"
        )


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
        self.floor = FloorTiles(camera, tiles, self.matcher, cfg.shift_rows, cfg.shift_cols)
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
        self._feats = np.stack([self.floor.features(self.floor.pool(image)) for image in subgoals])
        self._bands: dict[int, np.ndarray] = {}  # pooled taught bands of the last few subgoals
        self.growth = Growth(cfg)

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
        """The unmatched share of the floor tiles outside the path region of the last view scored."""
        view = as_frame(view, self.subgoals.shape[1:3])
        outside = np.flatnonzero(self.weights == 0)
        if not len(outside):
            return 0.0
        d = self._distances(view, position, outside)
        return float(np.count_nonzero(d[outside] > self.cfg.tile_threshold)) / len(outside)

    def _distances(
        self, view: Frame, position: float, active: np.ndarray, exhaustive: bool = False
    ) -> np.ndarray:
        """:meth:`scores` for the tiles ``active`` (indices into ``floor.tiles``), 0 for the others."""
        floor, thr = self.floor, -1.0 if exhaustive else self.cfg.tile_threshold
        d = np.zeros(len(floor.tiles), dtype=np.float32)
        if not len(active):
            return d
        own = floor.frame_features(view, active)  # the localiser's tile moments of this frame, shared
        k, offset = taught_offset(self.poses, position)
        d[active] = self.matcher.tile_distances(own, self._feats[k : k + 2, active]).min(axis=0)
        todo = np.flatnonzero(d[active] > thr)  # positions in active
        if not len(todo):
            return d
        band = self._bands.get(k)
        if band is None:
            if len(self._bands) >= 4:
                self._bands.clear()
            band = self._bands[k] = floor.pool(self.subgoals[k])
        warped = floor.warp(band, offset)
        for shifted in (False, True):
            views = floor.features(warped, active[todo], shifted)
            best = self.matcher.tile_distances(own[todo], views).min(axis=0)
            d[active[todo]] = np.minimum(d[active[todo]], best)
            todo = todo[d[active[todo]] > thr]
            if not len(todo):
                break
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

    def update(self, view: np.ndarray, position: float, moved: bool) -> ObstructionVerdict:
        """Judge one view (see :meth:`scores`); ``moved``: the robot was commanded to move (forward or
        turning, :func:`moving`) since the last view."""
        share, hidden = self.shares(self.scores(view, position))
        if not self.weights.any():
            self.growth.unseen()
        return self.growth.update(share, hidden, moved, lambda: self.elsewhere(view, position))


__all__ = [
    "FORWARD_SPEED",
    "TURN_SPEED",
    "Growth",
    "ObstructionConfig",
    "ObstructionDetector",
    "ObstructionVerdict",
    "moving",
]
