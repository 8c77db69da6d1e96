"""The camera-only obstruction detector's settings and its decision (runtime.obstruction judges the views):
:class:`Growth` folds each view's unmatched share of the path region into ``blocked`` or not, as the
detector's docstring says (a growth while the robot moves, from a matched floor, reaching the far end, with
the floor beside the path still matching; held until the way clears).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

#: The floor beside the path region in one view: its (unmatched, judged) tiles (ObstructionDetector.beside_tiles).
Elsewhere = Callable[[], "tuple[int, int]"]

T = TypeVar("T")


def once(fn: Callable[[], T]) -> Callable[[], T]:
    """``fn``, called at most once: later calls give its first answer (a view's evidence, asked lazily and maybe
    twice)."""
    memo: list[T] = []

    def call() -> T:
        if not memo:
            memo.append(fn())
        return memo[0]

    return call


@dataclass(frozen=True)
class ObstructionConfig:
    """The detector's settings; chosen on development routes only (evaluation/README.md)."""

    #: A tile's distance (matcher units: 0 same, ~1.13 unrelated textures) above which it is unmatched.
    tile_threshold: float = 0.55
    #: The matcher's floor on a tile's spread (0..255 units), higher than for localising: a plain patch of
    #: floor under a light that changes across it (one side darker) must stay plain.
    std_floor: float = 8.0
    #: How far the warped taught view is shifted each way, down and across, in degrees of the camera's view:
    #: the robot's pose error moves the floor by an angle, which a narrower camera spreads over more pixels.
    #: 1 and 2 pooled pixels (2 image pixels each) on the 90 deg, 128 px camera the defaults were tuned on
    #: (``ObstructionDetector`` rounds them to pooled pixels of the robot's camera).
    shift_rows_deg: float = 1.8
    shift_cols_deg: float = 3.6
    #: Metres ahead and behind the pose the robot is placed at that the taught floor is also warped to, where
    #: tiles stay unmatched there: the localiser's estimate lags or leads by up to this (dev offset_10cm_10deg,
    #: gen_104: 10 cm behind the robot; 0: no such tries).
    along_m: float = 0.1
    #: The path region: half the corridor's width and its near and far ends ahead of the camera (m).
    half_width_m: float = 0.2
    near_m: float = 0.3
    far_m: float = 1.5
    #: The most a plain tile's colour (chromaticity against the view's floor, runtime.floor_view's
    #: ``FloorTiles.colours``; L1) may differ from the taught view's for it to match: texture is normalised
    #: away on a plain tile (dev gen_107: a blue box face on a magenta floor cell, 0.32; the floor it
    #: matched elsewhere in the view, 0.03-0.11).
    colour_threshold: float = 0.2
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
    #: ... and the most where the path region was never seen matched to grow from (unmatched from its first
    #: view on, or in view first after a turn at the start): then only the floor beside it says that something
    #: stands on the path rather than the floor itself changed, and a floor a third or more unmatched does not
    #: say it (dev gen_100-179, seeds 0 1, pooled at the block: a re-coloured floor 0.31-0.48 on 13 false stops, every
    #: box on the path or after a turn 0.08-0.16 on 34 stops; where the region grew from a matched view, boxes
    #: on the path read up to 0.43 and a crossing obstacle 0.50).
    max_elsewhere_assumed: float = 0.25

    def pooled_shifts(self, focal: float) -> tuple[int, int]:
        """The warped taught view's shifts each way (pooled pixels, down and across) on a camera whose focal
        length is ``focal`` pooled pixels: the configured angles there, so a camera of another field of view or
        resolution tolerates the same pose error (1 and 2 on the 90 deg, 128 px camera)."""
        return (
            int(round(math.radians(self.shift_rows_deg) * focal)),
            int(round(math.radians(self.shift_cols_deg) * focal)),
        )

    def __post_init__(self) -> None:
        if not (isinstance(self.along_m, (int, float)) and 0.0 <= self.along_m <= 1.0):
            raise ValueError(f"ObstructionConfig.along_m must be in [0, 1] m, got {self.along_m!r}")
        for name in ("tile_threshold", "std_floor", "half_width_m", "near_m", "far_m", "colour_threshold"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"ObstructionConfig.{name} must be a finite number > 0, got {value!r}")
        if self.far_m <= self.near_m:
            raise ValueError(f"ObstructionConfig.far_m ({self.far_m}) must exceed near_m ({self.near_m})")
        fractions = ("onset_fraction", "block_fraction", "min_growth", "slack", "max_base", "hidden_fraction")
        fractions += ("min_region",)
        for name in (*fractions, "clear_fraction", "clear_hidden", "max_elsewhere", "max_elsewhere_assumed"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 <= value <= 1.0):
                raise ValueError(f"ObstructionConfig.{name} must be in [0, 1], got {value!r}")
        if not 0 < self.block_fraction or self.onset_fraction > self.block_fraction:
            raise ValueError(
                f"ObstructionConfig: need 0 < block_fraction and onset_fraction <= block_fraction, got "
                f"{self.onset_fraction}, {self.block_fraction}"
            )
        if self.max_elsewhere_assumed > self.max_elsewhere:
            raise ValueError(
                f"ObstructionConfig.max_elsewhere_assumed ({self.max_elsewhere_assumed}) must not exceed "
                f"max_elsewhere ({self.max_elsewhere})"
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
        for name in ("shift_rows_deg", "shift_cols_deg"):
            value = getattr(self, name)
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            if not (ok and 0.0 <= value <= 30.0):
                raise ValueError(f"ObstructionConfig.{name} must be 0 to 30 degrees, got {value!r}")
        for name, least in (("grow_steps", 1), ("clear_steps", 1)):
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
        # the least share since the region last matched (the unmatched spell's start); none seen yet: the first
        # view sets it (``update``)
        self.low = 1.0
        self.growing = 0  # moving steps since then without a drop of more than slack
        self.blocked = False
        self.clear = 0
        self.fresh = False  # the path came into view unmatched: no matched view of it to grow from
        self.seen = False  # any view of the path region judged yet
        # no view of the path region has matched to grow from: its matched start is assumed from the floor
        # beside it (``max_elsewhere_assumed``)
        self.assumed = False
        self._beside_spell()

    def _beside_spell(self) -> None:
        """Forget the floor beside the path: the unmatched and judged tiles pooled over the views asked since the
        path region went unmatched (:meth:`_pool_beside`)."""
        self.beside_unmatched = self.beside_judged = 0

    def unseen(self) -> None:
        """No floor of the path in view (it turns out of view): the next region seen is new. It may grow
        from unmatched only where the floor matched before the path went out of view (or none was seen
        yet): a floor that matched nowhere before the turn (re-laid) tells nothing after it either."""
        if not self.blocked:
            self.assumed = self.assumed or not self.seen  # nothing of the path seen before the turn
            self.fresh = self.fresh or self.low <= self.cfg.max_base or not self.seen
            self.growing, self.last, self.low = 0, 0.0, 1.0
            self._beside_spell()

    def _pool_beside(self, elsewhere: Elsewhere) -> None:
        """Add this view's floor beside the path region (``elsewhere``: its unmatched and judged tiles) to the
        spell's: one view judges 10-25 tiles, and on a re-coloured floor the share beside the path read 60-93%
        view after view while a growth blocked on the one view it read 50% (dev floor_recoloured gen_104,
        gen_109, gen_120, gen_125, gen_133); the floor does not change back between two views, a box does not
        change it."""
        unmatched, judged = elsewhere()
        self.beside_unmatched += unmatched
        self.beside_judged += judged

    def _floor_changed(self, bound: float) -> bool:
        """Whether more than ``bound`` of the floor beside the path region is unmatched, pooled over every view
        asked in this unmatched spell (:meth:`_pool_beside`)."""
        return self.beside_judged > 0 and self.beside_unmatched > bound * self.beside_judged

    def update(
        self, share: float, hidden: float, moved: bool, elsewhere: Elsewhere | None = None
    ) -> ObstructionVerdict:
        """Fold one view's unmatched share and hidden share in: the verdict. ``elsewhere``: the unmatched and
        judged tiles of the floor beside the path region in this view, asked only when everything else says
        blocked (or on the first view, unmatched)."""
        cfg = self.cfg
        asked = False

        def floor_changed(bound: float = cfg.max_elsewhere) -> bool:
            nonlocal asked
            if elsewhere is None:
                return False
            if not asked:  # the view's tiles pooled once, however often it is asked
                self._pool_beside(elsewhere)
                asked = True
            return self._floor_changed(bound)

        if self.blocked:
            clear = share <= cfg.clear_fraction or hidden <= cfg.clear_hidden
            self.clear = self.clear + 1 if clear else 0
            if self.clear >= cfg.clear_steps:
                self.reset()
                note = f"way clear: path region {share:.0%} unmatched, {hidden:.0%} up to its far end"
                return ObstructionVerdict(False, share, 0, note, hidden)
            return ObstructionVerdict(True, share, self.growing, self.note(share), hidden)
        if not self.seen and share >= cfg.onset_fraction and elsewhere is not None:
            # unmatched from the first view on: something on the path already in view where the floor beside
            # it matches (a box just past a turn near the start, dev box_after_turn gen_102), else the floor
            # itself changed (re-laid), and nothing grew from a matched floor
            self.low = 1.0 if floor_changed() else 0.0
            self.assumed = True
        self.seen = True
        if share < cfg.onset_fraction:
            self.growing, self.low, self.fresh, self.assumed = 0, share, False, False
            self._beside_spell()
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
        bound = cfg.max_elsewhere_assumed if self.assumed else cfg.max_elsewhere
        if self.blocked and elsewhere is not None and floor_changed(bound):
            self.blocked = False  # the floor beside the path changed as much: not evidence of something on it
        note = self.note(share) if self.blocked else f"path region {share:.0%} unmatched"
        return ObstructionVerdict(self.blocked, share, self.growing, note, hidden)

    def note(self, share: float) -> str:
        return (
            f"view ahead blocked: {share:.0%} of the path region unmatched, growing for {self.growing} steps"
        )


__all__ = ["Elsewhere", "Growth", "ObstructionConfig", "ObstructionVerdict", "once"]
