"""Where the robot is along its taught route, and how sure: a discrete Bayes filter over route positions.

The state is the robot's position ``s`` along the route in subgoal units (``s = 3.5``: half-way from
subgoal 3 to subgoal 4), held as a belief over a grid of ``cells_per_gap`` cells per gap. Each control step:

- **predict** (:meth:`RouteLocaliser.predict`): the command the robot was given moves the belief along the
  route by the share of the taught gap it covers. A gap's taught motion is a vector (distance, turn) from
  the taught poses; the command's (v dt, w dt) is projected onto it, so a drive on a straight, a turn in
  place and a curve all count, and a command against the taught direction counts back. The belief is
  blurred by the motion's uncertainty (a fraction of the move, plus a floor).
- **update** (:meth:`RouteLocaliser.update`): the view is compared with the subgoals in a window around the
  estimate. The expected distances at a position come from the teach itself: at subgoal k they are the
  taught images' distances to each subgoal of the window, and between subgoals they are interpolated. A
  repeat-time change (light, a shifted start, a moved chair) raises every distance alike, so each position
  is scored by its residuals after the best common offset; that offset is the match's quality.
- **observe** (:meth:`RouteLocaliser.observe`): where the floor places the robot (``runtime.pivot``) weighs it too.

Sequence matching of this kind (the view's distances to several neighbouring subgoals at once, against the
profile the teach itself shows) tells "just before subgoal 4" from "just after it" where one distance
cannot: that single distance is what the threshold rules of the earlier controller switched on. Nothing
here advances by time or by rule; the estimate moves because the commanded motion and the views say so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from vtr.runtime.frame import Frame
from vtr.runtime.matching import Matcher


@dataclass(frozen=True)
class LocaliserConfig:
    """The filter's settings; the defaults were chosen on development routes only (evaluation/README)."""

    #: Grid cells per gap between two subgoals.
    cells_per_gap: int = 4
    #: Subgoals compared with each view: this many behind the estimate and ahead of it.
    window_behind: int = 3
    window_ahead: int = 5
    #: Std of a command's progress: this fraction of the move, plus ``motion_floor`` gaps.
    motion_noise: float = 0.3
    motion_floor: float = 0.05
    #: Std of a residual distance, in units of the route's median gap.
    obs_sigma: float = 0.35
    #: Metres of travel a radian of turn weighs as, to put distance and turn in one progress.
    turn_length_m: float = 0.2
    #: Belief mass spread uniformly each step, so that a wrong estimate can be recovered from.
    mixing: float = 1e-4
    #: Horizontal shifts (pooled pixels, each way) the view is also compared at, against the subgoal the
    #: belief expects: a robot turned off the taught heading (closing a side offset) sees the taught view
    #: shifted sideways (Bearnav's registration); unregistered, a turn of 10 degrees matched no subgoal.
    shifts: tuple[int, ...] = (3, 6)
    #: ... only where the teach turned less than this (rad) in each gap beside that subgoal: in a turn the
    #: neighbouring subgoals are the view shifted sideways, and the heading is the position along the route
    #: (registered there, a robot turned past the end of a taught turn in place matched its last subgoal).
    register_turn: float = 0.05

    def __post_init__(self) -> None:
        if self.cells_per_gap < 1 or self.window_behind < 1 or self.window_ahead < 1:
            raise ValueError("cells_per_gap, window_behind and window_ahead must be >= 1")
        if not all(isinstance(s, int) and not isinstance(s, bool) and s > 0 for s in self.shifts):
            raise ValueError(f"shifts must be positive integers (pooled pixels), got {self.shifts!r}")
        for name in ("motion_noise", "motion_floor", "obs_sigma", "turn_length_m", "mixing", "register_turn"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if self.obs_sigma <= 0 or self.turn_length_m <= 0 or self.mixing >= 1:
            raise ValueError("obs_sigma and turn_length_m must be > 0 and mixing < 1")


@dataclass(frozen=True)
class Estimate:
    """The localiser's answer after a view.

    ``position``: the belief's mean near its mode, in subgoal units; ``std``: its spread (gaps);
    ``confidence``: the belief mass within ``CONFIDENT_SPAN`` gaps of the mode (0..1); ``match``: the common
    offset of the view's distances at the estimate (matcher units: 0 when the view is as the teach saw it);
    ``best``, ``best_error``: the subgoal of the window the view is closest to, and that distance;
    ``errors``: the window's distances, from subgoal ``first``; ``fit``: their rms about the teach's profile at
    the estimate, less ``match``, in units of the filter's observation noise (1: as noisy as it expects).
    """

    position: float
    std: float
    confidence: float
    match: float
    best: int
    best_error: float
    first: int
    errors: np.ndarray
    fit: float = math.nan

    def error_to(self, index: int) -> float:
        """The view's distance to subgoal ``index`` (nan when it was outside the window)."""
        k = index - self.first
        return float(self.errors[k]) if 0 <= k < len(self.errors) else math.nan


#: The fewest tiles across a view for it to be registered sideways: a shift drops one column of them.
REGISTER_COLUMNS = 4

#: Half-width (gaps) of the span around the mode whose mass is the confidence.
CONFIDENT_SPAN = 0.75


def _mean(x: np.ndarray, axis: int) -> np.ndarray:
    """``np.mean(x, axis)`` of a float64 array: the same sum and division, without its Python wrappers (the
    update runs a few of these on a small table every step)."""
    return np.add.reduce(x, axis=axis) / x.shape[axis]


def _shifted(belief: np.ndarray, cells: float) -> np.ndarray:
    """``belief`` moved by ``cells`` (a fraction split between the two cells it falls between), mass kept:
    what would move past either end of the route piles up there (the robot is at the end, not beyond it)."""
    n = len(belief)
    whole = math.floor(cells)
    frac = cells - whole
    src = np.arange(n) + whole
    # np.minimum / np.maximum: np.clip's own checks cost more than the clip on these few cells
    near = np.bincount(np.minimum(np.maximum(src, 0), n - 1), weights=belief * (1.0 - frac), minlength=n)
    return near + np.bincount(np.minimum(np.maximum(src + 1, 0), n - 1), weights=belief * frac, minlength=n)


class RouteLocaliser:
    """A belief over the position along a route of ``len(feats)`` subgoals (see the module docstring)."""

    def __init__(
        self,
        feats: np.ndarray,
        matcher: Matcher,
        motion: np.ndarray,
        median_gap: float,
        cfg: LocaliserConfig | None = None,
    ) -> None:
        """``feats``: the subgoals' features (``matcher.features``); ``motion``: (L-1, 2) from
        :func:`~vtr.runtime.kinematics.taught_motion`; ``median_gap``: the route's median distance between
        consecutive subgoals."""
        self.cfg = cfg or LocaliserConfig()
        self.matcher, self.feats = matcher, feats
        self.n = len(feats)
        k = self.cfg.cells_per_gap
        self.cells = np.arange((self.n - 1) * k + 1) / k  # positions of the grid, in subgoal units
        self.sigma = max(self.cfg.obs_sigma * float(median_gap), 1e-6)
        rho = self.cfg.turn_length_m
        self._motion = np.asarray(motion, dtype=np.float64).reshape(-1, 2) * (1.0, rho)
        self._motion_sq = np.einsum("ij,ij->i", self._motion, self._motion)
        self._gap_m = np.sqrt(self._motion_sq)  # each gap's taught travel (m, turns at ``rho`` a radian)
        # the taught travel from the first subgoal to each: window_travel's sums, the end by travel's route
        self._travelled = np.concatenate([[0.0], np.cumsum(self._gap_m)])
        # per subgoal: whether the teach drove on without turning much on either side (register_turn)
        turn = np.abs(np.asarray(motion, dtype=np.float64).reshape(-1, 2)[:, 1])
        before, after = np.concatenate([[0.0], turn]), np.concatenate([turn, [0.0]])
        self._straight = np.maximum(before, after) < self.cfg.register_turn
        self._shifts = tuple(s for size in self.cfg.shifts for s in (size, -size))  # each size, both ways
        if any(size >= matcher.cfg.patch for size in self.cfg.shifts):
            raise ValueError(
                f"shifts must be under the tile side ({matcher.cfg.patch}), got {self.cfg.shifts!r}"
            )
        # the teach's own distances, subgoal k to k + o for every offset o of the widest window
        self._span = self.cfg.window_behind + self.cfg.window_ahead + 1
        self._band = self._self_distances(self._span)
        # per window: the expected distances of its cells (the window moves a subgoal every few steps)
        self._expected_of: dict[tuple[int, int], tuple[np.ndarray, bool]] = {}
        for centre in range(self.n if self.n > 1 else 0):  # built with the route, not during the repeat
            self._expectation(self._window_at(centre))
        self.belief = np.zeros(len(self.cells))
        self.start_at(0.0)
        self.last: Estimate | None = None

    def _self_distances(self, span: int) -> np.ndarray:
        """(n, 2 * span + 1): distance of taught subgoal k to subgoal k + o - span (nan outside the route)."""
        band = np.full((self.n, 2 * span + 1), np.nan)
        for k in range(self.n):
            lo, hi = max(0, k - span), min(self.n, k + span + 1)
            band[k, lo - k + span : hi - k + span] = self.matcher.distances(self.feats[k], self.feats[lo:hi])
        return band

    def start_at(self, position: float | None) -> None:
        """A belief at ``position`` (subgoal units), or spread over the whole route (None: start anywhere)."""
        self._wide = position is None or self.n < 2
        if position is None or self._wide:
            self.belief[:] = 1.0 / len(self.belief)
            return
        self.belief[:] = np.exp(-0.5 * ((self.cells - position) / 0.25) ** 2)
        self.belief /= self.belief.sum()

    @property
    def wide(self) -> bool:
        """The next update compares the view with the whole route (start anywhere, or after a restart)."""
        return self._wide

    def progress(self, v: float, w: float, dt: float, position: float) -> float:
        """The share of the taught gap at ``position`` that the command (v, w) for ``dt`` covers."""
        if self.n < 2:
            return 0.0
        gap = min(int(position), self.n - 2)
        norm = self._motion_sq[gap]
        if norm < 1e-10:  # the teach stood still here: no motion tells progress
            return 0.0
        move = np.array([v * dt, self.cfg.turn_length_m * w * dt])
        return float(move @ self._motion[gap] / norm)

    def _command(self, v: float, w: float, dt: float) -> tuple[float, float]:
        """:meth:`progress` where the robot is, and the taught travel (m, either way) that is."""
        position = self.last.position if self.last is not None else self._mean()
        shift = self.progress(v, w, dt, position)
        return shift, abs(shift) * float(self._gap_m[min(int(position), self.n - 2)])

    def travel(self, v: float, w: float, dt: float) -> float:
        """The taught travel (m, a turn counted at ``turn_length_m`` a radian) that the command (v, w) for
        ``dt`` covers along the route where the robot is, either way: a drive on a straight counts its
        distance, a turn in place its turn (what :meth:`predict` returns)."""
        return 0.0 if self.n < 2 else self._command(v, w, dt)[1]

    @property
    def travelled(self) -> np.ndarray:
        """(n,) the taught travel (m, turns at ``turn_length_m`` a radian) from the first subgoal to each."""
        return self._travelled

    def predict(self, v: float, w: float, dt: float) -> float:
        """Move the belief by the command (v, w) for ``dt`` s; returns the taught travel it covered (:meth:`travel`)."""
        shift, travelled = self._command(v, w, dt) if self.n > 1 else (0.0, 0.0)
        if self._wide or self.n < 2:
            return travelled
        k = self.cfg.cells_per_gap
        std = (self.cfg.motion_noise * abs(shift) + self.cfg.motion_floor) * k  # in cells
        moved = _shifted(self.belief, shift * k)
        half = max(1, int(math.ceil(3 * std)))
        taps = np.exp(-0.5 * (np.arange(-half, half + 1) / max(std, 1e-6)) ** 2)
        self.belief = np.convolve(moved, taps / taps.sum(), mode="same")
        self._normalise()
        return travelled

    def _normalise(self) -> None:
        total = self.belief.sum()
        if not (math.isfinite(total) and total > 0):
            self.belief[:], total = 1.0, float(len(self.belief))
        self.belief /= total
        m = self.cfg.mixing
        self.belief = (1 - m) * self.belief + m / len(self.belief)

    def window_travel(self, position: float) -> float:
        """The taught travel (m, a turn counted at ``turn_length_m`` a radian) across the window of subgoals
        the views at ``position`` are compared with: how far a robot can get along the route and still be
        found by them."""
        if self.n < 2:
            return math.inf
        window = self._window_at(int(round(position)))
        return float(self._travelled[window.stop - 1] - self._travelled[window.start])

    def left_to_end(self, steps: float) -> float:
        """The belief's expectation of the taught motion left before the end, in control steps (``steps`` per
        gap), each position's counted up to one: 1 well before the end, 0 with all the belief at the end. (The
        belief piles up at the end when the robot drives past it, where the estimate's mean stays short.)"""
        return float(self.belief @ np.minimum(1.0, (self.cells[-1] - self.cells) * steps))

    def _mean(self) -> float:
        return float(self.belief @ self.cells)

    def window(self) -> range:
        """The subgoals the next view is compared with."""
        if self._wide:
            return range(0, self.n)
        return self._window_at(int(round(self.last.position if self.last is not None else self._mode())))

    def _window_at(self, centre: int) -> range:
        return range(max(0, centre - self.cfg.window_behind), min(self.n, centre + self.cfg.window_ahead + 1))

    def _expectation(self, win: range) -> tuple[np.ndarray, bool]:
        """The window's expected distances per cell (cached), and whether some are unknown (nan)."""
        key = (win.start, win.stop)
        if key not in self._expected_of:
            k = self.cfg.cells_per_gap
            table = self._expected(self.cells[win.start * k : (win.stop - 1) * k + 1], win)
            self._expected_of[key] = (table, bool(np.isnan(table).any()))
        return self._expected_of[key]

    def _mode(self) -> float:
        return float(self.cells[int(np.argmax(self.belief))])

    def update(self, view: Frame | np.ndarray) -> Estimate:
        """Weigh the belief by how well ``view`` fits each position: a frame, or the current image's features
        from the localiser's matcher (``matcher.features(frame)``, which a caller may need for more)."""
        frame = view if isinstance(view, Frame) else None
        if frame is not None:
            view = self.matcher.features(frame)
        win = self.window()
        errors = self.matcher.distances(view, self.feats[win.start : win.stop])
        if frame is not None and self.cfg.shifts and self._registers(frame):
            errors = self._registered(frame, errors, win)
        best = int(errors.argmin())
        if self.n < 2:
            self.last = Estimate(0.0, 0.0, 1.0, float(errors[0]), 0, float(errors[0]), 0, errors)
            return self.last
        k = self.cfg.cells_per_gap
        lo, hi = win.start * k, (win.stop - 1) * k + 1  # cells the window can judge
        expected, gaps = self._expectation(win)  # (cells, window)
        resid = errors[None, :] - expected
        mean = np.nanmean if gaps else _mean  # subgoals beyond the band: only in a whole-route window
        offset = mean(resid, axis=1)
        resid -= offset[:, None]
        sq = mean(resid * resid, axis=1)
        loglik = -0.5 * sq / self.sigma**2 * min(len(win), 4)
        like = np.exp(loglik - loglik.max())
        outside = like.min()  # a position the window cannot judge is taken as no better than its worst
        weights = np.full(len(self.belief), outside)
        weights[lo:hi] = like
        self.belief *= weights
        self._normalise()
        self._wide = False
        mean, std, confidence = self._spread()
        at = min(max(round(mean * k), lo), hi - 1) - lo
        self.last = Estimate(
            position=mean,
            std=std,
            confidence=confidence,
            match=float(max(offset[at], 0.0)),
            best=win.start + best,
            best_error=float(errors[best]),
            first=win.start,
            errors=errors,
            fit=float(np.sqrt(sq[at])) / self.sigma,
        )
        return self.last

    def _spread(self) -> tuple[float, float, float]:
        """The belief's mean near its mode, its spread there, and the mass within ``CONFIDENT_SPAN`` of the mode."""
        k = self.cfg.cells_per_gap
        mode = int(self.belief.argmax())
        a, b = max(0, mode - 3 * k), min(len(self.belief), mode + 3 * k + 1)  # three gaps either side
        local = self.belief[a:b] / self.belief[a:b].sum()
        mean = float(local @ self.cells[a:b])
        std = math.sqrt(max(float(local @ (self.cells[a:b] - mean) ** 2), 0.0))
        near = int(round(CONFIDENT_SPAN * k))
        return mean, std, float(self.belief[max(0, mode - near) : mode + near + 1].sum())

    def observe(self, position: float, std: float) -> Estimate:
        """After :meth:`update`: weigh the belief by where the floor places the robot (``position`` give or take
        ``std``, subgoal units; ``runtime.pivot``). The view's distances in the estimate stay as they were."""
        assert self.last is not None, "observe follows update"
        self.belief *= np.exp(-0.5 * ((self.cells - position) / max(std, 1e-6)) ** 2)
        self._normalise()
        return self._respread()

    def at_least(self, position: float) -> Estimate:
        """After :meth:`update`: the floor places the robot at ``position`` or past it (``runtime.turn_end``):
        the belief short of it moves there (not mixed: a mean a hair short would still be in the gap before)."""
        assert self.last is not None, "at_least follows update"
        cut = int(round(position * self.cfg.cells_per_gap))
        self.belief[cut] += self.belief[:cut].sum()
        self.belief[:cut] = 0.0
        return self._respread()

    def _respread(self) -> Estimate:
        """The last estimate with the position, spread and confidence of the belief as it is now."""
        assert self.last is not None
        mean, spread, confidence = self._spread()
        self.last = replace(self.last, position=mean, std=spread, confidence=confidence)
        return self.last

    def _registers(self, frame: Frame) -> bool:
        """Whether views are registered sideways: patch matching, ``REGISTER_COLUMNS`` tiles across or more."""
        return self.matcher.cfg.method == "patch" and self.matcher.tile_columns(frame) >= REGISTER_COLUMNS

    def _registered(self, frame: Frame, errors: np.ndarray, win: range) -> np.ndarray:
        """``errors``, and the window's distances at the sideways shift that lines the view up best with the
        subgoal the belief expects (the closest one where it has no prior), where those are lower."""
        near = int(errors.argmin()) if self._wide else int(round(self._mean())) - win.start
        near = min(max(near, 0), len(errors) - 1)
        if not self._straight[win.start + near]:
            return errors
        target = self.feats[win.start + near : win.start + near + 1]
        d = self.matcher.shifted_distances(frame, self._shifts, target)[:, 0]
        best = int(d.argmin())
        if not d[best] < errors[near]:
            return errors
        window = self.matcher.shifted_distances(frame, self._shifts, self.feats[win.start : win.stop], best)
        return np.minimum(errors, window[best])

    def _expected(self, pos: np.ndarray, win: range) -> np.ndarray:
        """(len(pos), len(win)) distances the teach predicts at each position to each subgoal of the window."""
        k0 = np.minimum(np.floor(pos).astype(int), self.n - 2)
        frac = (pos - k0)[:, None]
        cols = np.arange(win.start, win.stop)[None, :]
        span = self._span
        a = self._band[k0[:, None], np.clip(cols - k0[:, None] + span, 0, 2 * span)]
        b = self._band[k0[:, None] + 1, np.clip(cols - k0[:, None] - 1 + span, 0, 2 * span)]
        far_a = np.abs(cols - k0[:, None]) > span
        far_b = np.abs(cols - k0[:, None] - 1) > span
        a = np.where(far_a, np.nan, a)
        b = np.where(far_b, np.nan, b)
        return (1 - frac) * a + frac * b
