"""How far beside the taught path the robot is: the floor seen now against the floor the teach saw.

A pinhole camera above a flat floor sees each image row below the horizon at a known distance ``X`` ahead
(``runtime.floor_view``). A robot ``dy`` to the left of the taught pose and turned ``psi`` to the left sees
every floor row shifted sideways by ``f (psi + dy / X)`` pixels: the far rows tell the heading, the near rows
the side offset. Each floor row of the current view is compared with the same row of the taught view (warped
by the floor plane to the taught pose at the localiser's estimate, between two subgoals) under whole-pixel
shifts, the best shift refined to a fraction, and a line through shift against ``1 / X`` gives ``(dy, psi)``.

The estimate places the robot along the route only to a few centimetres, and a robot that far from the taught
pose sees other floor in each row: on a floor whose edges cross the rows at a slant, that reads as a side
offset (dev houses: 11 mm rms error with the estimate within a centimetre of the robot, 43 mm 4-8 cm off it,
a mirror of the true offset further on, which the side turn then widened). So where the floor tells a
distance along the route, the taught rows are warped to a few offsets along it around the estimate, searched
further where the best is the furthest tried, and ``(dy, psi)`` is fitted where the floor matches best
(``SideConfig.along_search``); a best at the furthest reach tells nothing, and nor does one that an offset
further along matches nearly as well while reading another side offset (planks laid at a slant to the path,
where a step along the route looks as a step beside it does).

Why the follower needs it: VelocityNet turns until the view lines up with the subgoal's, and the walls it
lines up have no known distance, so a view ``dy`` to the side looks like one turned by ``dy / D`` for walls
``D`` away. The policy alone therefore closes a side offset only over a few times ``D`` of travel (dev routes,
a start 10 cm to the side: still 5 cm off after 1.5 m). The floor's rows, whose distances are known, tell the
two apart. Rows are normalised per channel (a change of light drops out) and a row whose best shift is not
clearly better than the others (a plain or re-coloured floor, furniture standing on the row) is left out; with
too few rows left there is no estimate, and the follower steers by VelocityNet alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.lib.stride_tricks import as_strided

from vtr.runtime.floor_view import Camera, FloorTiles, taught_offset
from vtr.runtime.matching import MatchConfig, Matcher


@dataclass(frozen=True)
class SideConfig:
    """The floor rows used and how sure a row's shift must be (defaults chosen on dev routes 100-105)."""

    #: Floor rows from this near to this far ahead (m): nearer rows are cut by the image's bottom edge, and
    #: further ones are often a wall or furniture (whose rows all shift alike, as a turn would).
    near_m: float = 0.35
    far_m: float = 1.2
    #: Largest shift tried each way, as an angle (rad): a row's shift is f (psi + dy / X) pixels, so this bounds
    #: psi + dy / X whatever the camera's field of view or resolution (12 pooled pixels of the 90 deg, 128 px
    #: camera, whose focal length is 32 of them: a side offset of 10 cm is 9 of them on the nearest row). As a
    #: share of the image's width it was 37 deg each way on a 120 deg camera, where a row's best shift was as
    #: often a wrong one (dev houses at 120 deg: 27/40 completed, 36/40 with the angle).
    max_shift_rad: float = 0.375
    #: A row counts when its best score (mean absolute difference of normalised values: 0 the same row,
    #: about 1.1 unrelated ones) is under ``match`` and its median over the shifts ``distinct`` above it.
    match: float = 0.6
    distinct: float = 0.1
    #: ... and an estimate needs this share of the rows to agree on one line.
    min_share: float = 0.7
    #: Rows whose shift is this far off the fitted line, as an angle (rad), are dropped and the line fitted
    #: again (1.5 pooled pixels of the 90 deg, 128 px camera).
    outlier_rad: float = 1.5 / 32
    #: A registration along the route (:meth:`SideOffset.along`) tells the robot has arrived only where its best
    #: offset scores this much under every offset two or more steps from it that would put the robot short
    #: (median row, as ``distinct``; ``runtime.arrival``). Where the floor tells little the scores lie within a
    #: few hundredths of each other and the lowest is where noise put it: on dev houses 900-999, of the
    #: readings that ended a run, 5 of 33 with margins (over every offset two or more steps away) under 0.06
    #: were 3-7 cm off the robot, none of 68 over 0.06 more than 2 cm.
    along_margin: float = 0.07
    #: The side offset is registered at this many of :meth:`SideOffset.along`'s steps each way along the route
    #: around the localiser's estimate, and taken where the floor matches best; where the best is the furthest
    #: tried, the search goes on that way as many steps again, up to ``along_reach`` steps from the estimate, and
    #: where the best is still the furthest tried, the floor tells no side offset. 0: at the estimate.
    along_search: int = 2
    along_reach: int = 6
    #: ... and the best must score under every offset two or more steps from it (those within ``along_search``
    #: of the estimate and every ``along_search``-th out to ``along_reach``); where one scores within
    #: ``along_distinct`` of it and reads a side offset more than ``rival_side_m`` from the best's, the floor
    #: tells none: a floor that repeats along the path (planks at a slant) matches nearly as well at other
    #: offsets, each with its own side offset (dev house random:943: readings 30-50 mm off, read at whichever
    #: offset noise favoured).
    along_distinct: float = 0.08
    rival_side_m: float = 0.05


@dataclass(frozen=True)
class SideEstimate:
    """The robot's offset from the taught pose at the estimate: ``dy`` metres to the left, ``psi`` radians
    turned to the left; ``rows``: the floor rows that agreed; ``dx``: metres ahead of that pose, where the
    floor was registered along the route too (:meth:`SideOffset.along`; else 0, the localiser's estimate), and
    ``margin``: by how much the best offset along scored under its rivals (inf where it has none: one clear
    valley, or the lowest of a flat row of scores: ``SideConfig.along_margin``)."""

    dy: float
    psi: float
    rows: int
    dx: float = 0.0
    margin: float = math.inf


class SideOffset:
    """Register views against the taught views' floor (see the module docstring)."""

    def __init__(
        self, subgoals: np.ndarray, poses: np.ndarray, camera: Camera, cfg: SideConfig | None = None
    ) -> None:
        self.cfg = cfg = cfg or SideConfig()
        self.matcher = Matcher(MatchConfig())
        h, w = subgoals.shape[1:3]
        self.camera = camera = Camera(h, w, camera.fov_deg, camera.height_m)
        ds = self.matcher.cfg.downsample
        tiles = np.arange((h // ds // self.matcher.cfg.patch) * (w // ds // self.matcher.cfg.patch))
        self.floor = FloorTiles(camera, tiles[len(tiles) // 2 :], self.matcher)  # the band from the horizon
        top = self.floor.top
        down, _ = camera.rays(np.arange(top, h // ds) * ds + ds / 2, np.zeros(1))
        ahead = np.where(down > 0, camera.height_m / np.where(down > 0, down, 1.0), np.inf)
        self.rows = np.flatnonzero((ahead >= cfg.near_m) & (ahead <= cfg.far_m))
        self.min_rows = max(3, int(math.ceil(cfg.min_share * len(self.rows))))
        if len(self.rows) < 4:
            raise ValueError(f"a {h}x{w} camera sees too few floor rows {cfg.near_m}-{cfg.far_m} m ahead")
        self.focal = camera.focal_px / ds  # in pooled pixels
        self.shifts = max(2, round(cfg.max_shift_rad * self.focal))
        self.outlier = cfg.outlier_rad * self.focal  # in pooled pixels
        if w // ds - 2 * self.shifts < 4:
            raise ValueError(f"a {h}x{w} camera is too narrow to shift its floor rows {self.shifts} pixels")
        # the floor point each kept pooled pixel sees: ahead (m, per row) and -side * ahead to the left
        self._ahead = ahead[self.rows].astype(np.float32)
        self._side = camera.rays(np.zeros(1), np.arange(w // ds) * ds + ds / 2)[1].astype(np.float32)
        self._row_scale = np.float32(camera.focal_px * camera.height_m / ds)
        self._row_zero = np.float32(h / 2 / ds - top)
        self._design = np.stack([np.ones(len(self.rows)), 1.0 / ahead[self.rows]], axis=1)
        self.subgoals, self.poses = subgoals, np.asarray(poses, dtype=np.float64)
        self._bands: dict[int, np.ndarray] = {}
        self._along_told: dict[int, bool] = {}  # per taught view: whether its floor tells a distance along
        n = len(self.rows)
        self._cols = w // ds - 2 * self.shifts  # the current rows' middle columns compared
        self._r = np.arange(n)
        self._around = np.array([[-1], [0], [1]])  # a shift's neighbours, for the sub-pixel fit
        #: the spacing (m) of ``along``'s candidates: 1.5 pooled pixels on the nearest row kept
        self.along_step = float(1.5 * self._ahead.min() ** 2 / (self.focal * camera.height_m))

    # Floor rows are laid out column-major: (cols, D, rows, 3) for D taught offsets, (cols, rows, 3) for the
    # current view, each kept row with its colours innermost. Every reduction below is then along the first
    # axis, over arrays whose inner run is all offsets, rows and colours (2-3 thousand values), where numpy is
    # fast; laid out row by row the same sums ran over runs of 40-64 values and cost 2-3 times as much
    # (numpy's per-run overhead). A score's sum runs over the columns in order, then over the colours, the
    # same for any D: an offset scored in a batch gives the bits it gives alone.

    def _band(self, k: int) -> np.ndarray:
        """Taught view ``k``'s pooled floor band, (band rows, cols, 3)."""
        if k not in self._bands:
            self._bands[k] = np.ascontiguousarray(self.floor.pool(self.subgoals[k]).transpose(1, 2, 0))
        return self._bands[k]

    def _normalised(self, rows: np.ndarray) -> np.ndarray:
        """(cols, ...) floor rows normalised in place (and returned), each row and channel at zero mean and unit
        spread (floored) over the columns."""
        cols = rows.shape[0]
        flat = rows.reshape(cols, -1)
        mean = np.add.reduce(flat, axis=0)
        mean /= cols
        flat -= mean
        spread = np.add.reduce(flat * flat, axis=0)
        spread /= cols
        np.sqrt(spread, out=spread)
        spread += self.matcher.cfg.std_floor * self.matcher.cfg.downsample**2
        flat /= spread
        return rows

    def _taught_rows(self, band: np.ndarray, offset: tuple[float, float, float]) -> np.ndarray:
        """(cols, 1, rows, 3): the kept rows of a taught band as the floor looks ``offset`` (ahead, left,
        turned left) from where it was taught (``FloorTiles.warp``'s plane, nearest pooled pixel, only the rows
        used here)."""
        dx, dy, turn = offset
        if not (dx or dy or turn):
            return np.ascontiguousarray(band[self.rows].transpose(1, 0, 2))[:, None]
        return self._warped_rows(band, np.array([dx], np.float32), dy, turn)

    def _warped_rows(self, band: np.ndarray, dx: np.ndarray, dy: float, turn: float) -> np.ndarray:
        """(cols, D, rows, 3): :meth:`_taught_rows` at each of the float32 ``dx`` with ``dy`` and ``turn``."""
        c, s = np.float32(math.cos(turn)), np.float32(math.sin(turn))
        ahead, side = self._ahead[None, None, :], self._side[:, None, None]
        inverse = 1.0 / np.maximum(ahead * (c + s * side) + dx[None, :, None], np.float32(1e-3))
        left = (ahead * (s - c * side) + np.float32(dy)) * inverse
        rows, cols = band.shape[:2]
        # np.minimum(np.maximum()) is np.clip's arithmetic without its Python wrapper (~10 us a call)
        row = np.minimum(np.maximum(inverse * self._row_scale + self._row_zero, 0), rows - 1).astype(np.intp)
        col = np.minimum(np.maximum(left * -self.focal + cols / 2, 0), cols - 1).astype(np.intp)
        row *= cols
        row += col
        # take gathers the pixels' three colours in about a quarter of fancy indexing's time
        return band.reshape(-1, 3).take(row, axis=0)

    def estimate(self, view: np.ndarray, position: float) -> SideEstimate | None:
        """The offset of ``view`` (a frame or an image) from the taught pose at route ``position`` (subgoal
        units), or None where the floor does not tell (see the module docstring)."""
        k, offset = taught_offset(self.poses, position)
        taught = self._band(k)  # seen from the taught pose at the position (between subgoals k and k + 1)
        n = self.cfg.along_search
        if not n or not self.tells_along(k):  # a floor the same along the path tells the side wherever
            return self._fit(self._table(self._current(view), self._taught_rows(taught, offset))[0])
        # elsewhere a robot a few centimetres off the estimate along the route sees other floor in each row (see
        # the module docstring): read it where the floor matches best along the route
        ahead, left, turn = offset
        cur = self._current(view)
        reach = self.cfg.along_reach
        found: dict[int, tuple[np.ndarray, float]] = {}  # offset along (steps) -> its table and score

        def score(offsets: range | list[int]) -> None:
            new = np.array([a for a in offsets if a not in found], dtype=np.intp)
            if new.size:
                rows = self._warped_rows(
                    taught, (ahead + new * self.along_step).astype(np.float32), left, turn
                )
                tables = self._table(cur, rows)
                found.update(
                    zip(new.tolist(), zip(tables, self._row_score(tables).tolist(), strict=True), strict=True)
                )

        # the offsets near the estimate, and every n-th out to the reach: the rivals a best must beat
        score([*range(-n, n + 1), *(a for a in range(-reach, reach + 1, n) if abs(a) > n)])
        lo, hi = -n, n
        while True:  # the best near the estimate; where it is the furthest tried, look on that way
            best = min(range(lo, hi + 1), key=lambda a: found[a][1])
            if best == lo > -reach:
                lo = max(-reach, lo - n)
            elif best == hi < reach:
                hi = min(reach, hi + n)
            else:
                break
            score(range(lo, hi + 1))
        if best in (lo, hi):  # the best at the furthest reach: the robot may be further off still
            return None
        # a floor that repeats along the path (planks laid across it at a slant) matches nearly as well at
        # offsets further along, each with its own side offset: no reading where such a rival reads another one
        table, least = found[best]
        rivals = [(a, s) for a, (_, s) in found.items() if abs(a - best) >= 2]
        if min((s for _, s in rivals), default=math.inf) < least:  # none where the reach is a step
            return None
        fit = self._fit(table)
        if fit is None:
            return None
        for a, s in rivals:
            if s - least < self.cfg.along_distinct:
                other = self._fit(found[a][0])
                if other is not None and abs(other.dy - fit.dy) > self.cfg.rival_side_m:
                    return None
        frac = float(_vertex(*(np.float64(found[a][1]) for a in (best - 1, best, best + 1))))
        # between the best offset and its neighbour toward the refined one, the fit moves with the offset
        near = self._fit(found[best + (1 if frac > 0 else -1)][0]) if frac else None
        dy, psi = (
            (fit.dy, fit.psi)
            if near is None
            else (fit.dy + abs(frac) * (near.dy - fit.dy), fit.psi + abs(frac) * (near.psi - fit.psi))
        )
        return SideEstimate(dy, psi, fit.rows, float((best + frac) * self.along_step))

    def along(
        self, view: np.ndarray, k: int, ahead: np.ndarray, rivals_below: float = math.inf
    ) -> SideEstimate | None:
        """The offset of ``view`` from taught pose ``k`` along its heading as well as beside it: the floor of
        subgoal ``k`` warped to each of ``ahead`` (m, ascending, evenly spaced; negative: short of the pose),
        the one whose rows match best (the median row's best score, refined between candidates) taken as
        ``dx``, and ``(dy, psi)`` fitted there, with the ``margin`` by which it scores under its rivals (the
        offsets two or more steps from it, those under ``rivals_below`` only); None where the best is at an end
        of ``ahead`` or the floor does not tell. A robot ``dx`` ahead sees the floor the teach saw ``X`` ahead
        at ``X - dx``: the near rows move by pixels per centimetre (1.3 cm a pooled pixel 0.35 m ahead on the
        90 deg, 128 px camera)."""
        if not self.tells_along(k):
            return None
        cur, band = self._current(view), self._band(k)
        # every candidate: a floor that tells little can score as well 6 cm away as at the best one (dev house
        # random:970, a robot 6 cm short: 0.128 there against 0.123 at the pose), and every other candidate
        # scored can miss that second valley
        tables = self._ahead_tables(cur, band, ahead)
        scores = self._row_score(tables).astype(np.float64)  # each a float32 score, as a Python float before
        i = int(scores.argmin())
        if not 0 < i < len(ahead) - 1:
            return None
        frac = _vertex(*scores[i - 1 : i + 2])
        found = self._fit(tables[i])
        if found is None:
            return None
        rivals = scores[(np.abs(np.arange(len(ahead)) - i) >= 2) & (ahead < rivals_below)]
        margin = float(rivals.min()) - float(scores[i]) if rivals.size else math.inf
        dx = float(ahead[i] + frac * (ahead[1] - ahead[0]))
        return SideEstimate(found.dy, found.psi, found.rows, dx, margin)

    def tells_along(self, k: int) -> bool:
        """Whether taught view ``k``'s floor tells a distance along the route: warped two of :meth:`along`'s
        steps either way, it differs from itself by more than ``distinct`` (a plain floor, or squares or planks
        laid along the path, shows the same rows over a stretch: sim2d's mosaic 0.15-0.46 on dev routes'
        ends, 20 cm squares laid along the path 0.06-0.08)."""
        if k not in self._along_told:
            cur, band = self._current(self.subgoals[k]), self._band(k)
            two = np.array([-2 * self.along_step, 2 * self.along_step])
            scores = self._row_score(self._ahead_tables(cur, band, two))
            self._along_told[k] = bool((scores > self.cfg.distinct).all())
        return self._along_told[k]

    def _ahead_tables(self, cur: np.ndarray, band: np.ndarray, ahead: np.ndarray) -> np.ndarray:
        """(D, shifts, rows) scores (:meth:`_table`) of the current rows against a taught band as seen from each
        of ``ahead`` (m, straight on), in one batch: the values one by one would give, without D rounds of small
        array calls (``along`` asks for 9-13)."""
        tables = np.empty((len(ahead), 2 * self.shifts + 1, len(self.rows)), np.float32)
        off = ahead != 0
        if off.any():
            tables[off] = self._table(cur, self._warped_rows(band, ahead[off].astype(np.float32), 0.0, 0.0))
        if not off.all():  # the pose itself: its rows as they lie (_taught_rows), scored apart
            tables[~off] = self._table(cur, self._taught_rows(band, (0.0, 0.0, 0.0)))
        return tables

    @staticmethod
    def _row_score(table: np.ndarray) -> np.ndarray:
        """The median floor row's best score of a (..., shifts, rows) table: how well the floor matches as a
        whole (one per leading index)."""
        best = table.min(axis=-2)
        middle = best.shape[-1] // 2
        return np.partition(best, middle, axis=-1)[..., middle]

    def _current(self, view: np.ndarray) -> np.ndarray:
        """(cols, rows, 3) the kept floor rows of ``view``, normalised."""
        return self._normalised(np.ascontiguousarray(self.floor.pool(view)[:, self.rows].transpose(2, 1, 0)))

    def _table(self, cur: np.ndarray, taught_rows: np.ndarray) -> np.ndarray:
        """(D, shifts, rows) scores of the current rows (cols, rows, 3) against each of D offsets' taught rows
        (cols, D, rows, 3) under each shift, from -s_max: the mean absolute difference over the middle columns
        and the colours."""
        ref = self._normalised(taught_rows)
        cols, d = ref.shape[:2]
        s_max, m = self.shifts, self._cols
        taught = ref.reshape(cols, -1)
        # the current rows' middle columns, once for each offset, against every window of the taught rows:
        # window i is a shift of s_max - i (the current column c against the taught c - s); the strided view is
        # what sliding_window_view makes, without its ~50 us of Python checks
        middle = np.empty((m, d, cur[0].size), np.float32)
        middle[...] = cur.reshape(cols, 1, -1)[s_max : s_max + m]
        step = taught.strides[0]
        windows = as_strided(
            taught, (2 * s_max + 1, m, taught.shape[1]), (step, step, taught.strides[1]), False
        )
        diff = np.subtract(windows, middle.reshape(m, -1))
        np.abs(diff, out=diff)
        per_colour = np.add.reduce(diff, axis=1).reshape(2 * s_max + 1, d, -1, 3)  # summed column by column
        table = per_colour[..., 0] + per_colour[..., 1]
        table += per_colour[..., 2]
        table /= 3 * m
        return table[::-1].transpose(1, 0, 2)

    def _fit(self, table: np.ndarray) -> SideEstimate | None:
        """``(dy, psi)`` from a (shifts, rows) table: each row's best shift, refined to a fraction, and the line
        through the rows that tell (see the module docstring); None where too few do."""
        s_max, r = self.shifts, self._r
        best = table.argmin(axis=0)
        at = np.minimum(np.maximum(best, 1), 2 * s_max - 1)
        lo, mid, hi = table[at + self._around, r]  # one gather for the best shift and its two neighbours
        shift = at - s_max + _vertex(lo, mid, hi)
        # the median of an odd number of shifts is the middle one of a partition (np.median's own way, less
        # its ~60 us of Python); the best score is the table's at the best shift
        quality = np.partition(table, s_max, axis=0)[s_max] - table[best, r]
        ok = (best == at) & (quality > self.cfg.distinct) & (mid < self.cfg.match)  # best not at an end
        for _ in range(2):  # fit, drop the rows off the line (not floor: furniture, a wall), fit again
            kept = np.count_nonzero(ok)
            if kept < self.min_rows:
                return None
            line = _weighted_line(self._design, shift, quality * ok)
            ok &= np.abs(self._design @ line - shift) <= self.outlier
            if np.count_nonzero(ok) == kept:  # no row dropped: a second fit would be this one
                break
        if np.count_nonzero(ok) < self.min_rows:
            return None
        psi, dy = line[0] / self.focal, line[1] / self.focal
        if not (math.isfinite(dy) and math.isfinite(psi)):
            return None
        return SideEstimate(float(dy), float(psi), int(np.count_nonzero(ok)))


def _vertex(lo: np.ndarray, mid: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The vertex of the parabola through three scores a step apart, in steps from the middle one and within half
    a step of it (0 where they do not curve up): the sub-step refinement of a best shift or a best offset."""
    curve = lo - 2 * mid + hi
    frac = np.zeros(np.shape(curve), np.result_type(curve))
    np.divide(0.5 * (lo - hi), curve, out=frac, where=curve > 1e-9)
    return np.minimum(np.maximum(frac, -0.5), 0.5)


def _weighted_line(design: np.ndarray, y: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(intercept, slope) of the weighted least-squares line through ``y`` against ``design``'s columns."""
    a = design * weights[:, None]
    lhs, rhs = a.T @ design, a.T @ y
    det = lhs[0, 0] * lhs[1, 1] - lhs[0, 1] * lhs[1, 0]
    if abs(det) < 1e-12:
        return np.array([math.nan, math.nan])
    return np.array([lhs[1, 1] * rhs[0] - lhs[0, 1] * rhs[1], lhs[0, 0] * rhs[1] - lhs[1, 0] * rhs[0]]) / det


__all__ = ["SideConfig", "SideEstimate", "SideOffset"]
