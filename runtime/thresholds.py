"""Switch thresholds from a taught route (the rules are in runtime.controller's docstring)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from vtr.runtime.matching import MatchConfig, Matcher

if TYPE_CHECKING:
    from vtr.runtime.controller import ControllerConfig

THRESHOLD_MODES = ("fixed", "calibrated", "per_subgoal", "hybrid")
#: Default bounds of a derived threshold, per matching method, in that method's units. The patch floor is
#: what 1-2 cm or 1 degree away from a subgoal scores: finer than the policy steers, and it keeps creeping
#: segments (subgoals 1 cm apart) switchable.
DEFAULT_BOUNDS = {"raw": (1.0, 64.0), "patch": (0.15, 0.8)}
#: "Lost" needs the best nearby match above this too (patch: about 4 gaps of 5 cm away; unrelated views
#: score 0.8-0.9), so routes whose median gap is tiny (creeping) do not stop on noise.
LOST_FLOOR = {"raw": 0.0, "patch": 0.6}
#: The lost test searches this many subgoals ahead at least (creeping subgoals are 1 cm apart).
LOST_WINDOW = 20
#: Below this median patch distance between consecutive subgoals the route is too plain for patch matching
#: (our house's routes: 0.37-0.46; a room of plain walls: 0.00-0.004) and the raw error is used.
PLAIN_ROUTE_GAP = 0.05


def gaps_between(matcher: Matcher, feats: np.ndarray) -> np.ndarray:
    """(L-1,) distances between consecutive features of one route."""
    return np.array(
        [matcher.distance(feats[k], feats[k + 1]) for k in range(len(feats) - 1)], dtype=np.float64
    )


def consecutive_errors(images: np.ndarray, match: MatchConfig | None = None) -> np.ndarray:
    """(L-1,) distances between consecutive subgoals of (L, H, W, 3) uint8 images (raw by default)."""
    matcher = Matcher(match or MatchConfig.paper())
    return gaps_between(matcher, matcher.features(images))


def _route_threshold(gaps: np.ndarray, cfg: ControllerConfig) -> float:
    return float(np.clip(cfg.calib_fraction * np.quantile(gaps, cfg.calib_quantile), *cfg.bounds))


def calibrate_e_m(images: np.ndarray, cfg: ControllerConfig) -> float:
    """One threshold from the route (rule in the module docstring); the fixed e_m if the route has one image."""
    d = consecutive_errors(images, cfg.match)
    return cfg.e_m if d.size == 0 else _route_threshold(d, cfg)


def _neighbour_gaps(gaps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per subgoal, the gap into it and the gap out of it (the first has no incoming gap and the last no
    outgoing one: each takes its other neighbour's)."""
    return np.concatenate([gaps[:1], gaps]), np.concatenate([gaps, gaps[-1:]])


def thresholds(gaps: np.ndarray, n: int, cfg: ControllerConfig) -> np.ndarray:
    """(n,) switch threshold of every subgoal from the (n-1,) consecutive distances ``gaps``."""
    if cfg.e_m_mode == "fixed" or n < 2:
        return np.full(n, cfg.e_m)
    if cfg.e_m_mode == "calibrated":
        return np.full(n, _route_threshold(gaps, cfg))
    incoming, outgoing = _neighbour_gaps(gaps)
    if cfg.e_m_mode == "hybrid":  # the route's threshold, raised where both neighbouring gaps are wide
        local = cfg.calib_fraction * np.minimum(incoming, outgoing)
        return np.clip(np.maximum(_route_threshold(gaps, cfg), local), *cfg.bounds)
    return np.clip(cfg.calib_fraction * incoming, *cfg.bounds)


def lost_bounds(gaps: np.ndarray, n: int, cfg: ControllerConfig, route_bound: float) -> np.ndarray:
    """(n,) per subgoal: ``route_bound``, or ``lost_factor`` times the wider of its two neighbouring gaps where
    that is more (a view 2 degrees off a subgoal inside a fast turn differs from it by more than two of the
    route's median gaps and is not lost)."""
    if n < 2:
        return np.full(n, route_bound)
    incoming, outgoing = _neighbour_gaps(gaps)
    return np.maximum(route_bound, cfg.lost_factor * np.maximum(incoming, outgoing))


def bound_between(bounds: np.ndarray, position: float) -> float:
    """The lost bound at ``position`` (subgoal units) from :func:`lost_bounds`' per subgoal: the larger of its two
    subgoals' (where the teach's neighbouring views differ more, as in a fast turn in place or facing a wall
    close up, often at a route's end, a view between them differs more too: dev routes ended `lost` 8-22
    degrees short of a final turn)."""
    last = len(bounds) - 1
    lo = min(max(int(math.floor(position)), 0), last)
    return float(max(bounds[lo], bounds[min(lo + 1, last)]))


@dataclass(frozen=True)
class RouteViews:
    """What both controllers derive from a route's subgoal images: the comparison in force (``cfg.match``, the
    raw error where the route is too plain for patch matching: ``fallback`` says why), the subgoals' features,
    the gaps between consecutive ones, the thresholds, the median gap and the lost bound."""

    cfg: ControllerConfig
    matcher: Matcher
    feats: np.ndarray
    gaps: np.ndarray
    fallback: str
    thresholds: np.ndarray
    median_gap: float
    lost_bound: float


def check_subgoals(subgoals: np.ndarray) -> None:
    """Refuse anything but (L, H, W, 3) uint8 subgoal images with L >= 1 (both controllers take these)."""
    if subgoals.dtype != np.uint8 or subgoals.ndim != 4 or subgoals.shape[0] < 1 or subgoals.shape[-1] != 3:
        raise ValueError(
            f"subgoals must be (L, H, W, 3) uint8 with L >= 1, got {subgoals.shape} {subgoals.dtype}"
        )


def route_views(subgoals: np.ndarray, cfg: ControllerConfig) -> RouteViews:
    """:class:`RouteViews` of (L, H, W, 3) uint8 ``subgoals`` under ``cfg``."""
    n = len(subgoals)
    matcher = Matcher(cfg.match)
    feats = matcher.features(subgoals)
    gaps = gaps_between(matcher, feats)
    fallback = ""
    if cfg.match.method == "patch" and n > 1 and np.median(gaps) < PLAIN_ROUTE_GAP:
        # Patch normalisation sees texture only: in a room of plain walls and floor consecutive taught views
        # differ by ~0 and every subgoal would "match". The raw error still sees the motion.
        fallback = f"patch matching sees no motion along this route (median gap {np.median(gaps):.3f})"
        cfg = replace(cfg, match=MatchConfig.paper())
        matcher = Matcher(cfg.match)
        feats = matcher.features(subgoals)
        gaps = gaps_between(matcher, feats)
    limits = thresholds(gaps, n, cfg)
    median_gap = float(np.median(gaps)) if n > 1 else float(limits[0])
    #: A view farther than this from every nearby subgoal is not on the route (see LOST_FLOOR).
    lost_bound = max(cfg.lost_factor * median_gap, LOST_FLOOR[cfg.match.method])
    if n < 2 or gaps.max() < DEFAULT_BOUNDS[cfg.match.method][0] / 10:
        lost_bound = math.inf  # a route whose views barely change cannot tell being lost
    return RouteViews(cfg, matcher, feats, gaps, fallback, limits, median_gap, lost_bound)
