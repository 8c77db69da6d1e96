"""Stop for what is in the way: the range-scan half of the repeat's safety layer.

The idea of Nav2's collision_monitor, on our robot: zones filled by the points of the latest range scan,
each with an action. Given the commanded twist (v, w) and a :class:`Scan`, :func:`limit_twist` projects
the scan's points into the robot frame (the scanner sits ``x_m`` ahead of the centre) and keeps those in
the robot's way: the path its footprint, grown by ``margin``, sweeps as it drives on along the commanded
arc (ahead for v >= 0, behind for v < 0; straight ahead while it stands or turns in place), like the
footprint collision_monitor's approach model projects along the twist. On a taught route the path bends
where the route turns in place (``SafetyConfig.bend``, from :func:`taught_zones`): up to the turn along the
arc, then along the heading after it, and nothing past the route's end; so what stands beside the leg after
a turn, straight ahead of the robot driving to it, is not in the way. Of the points in the way, the
nearest (straight from the grown footprint, never more than the travel to it, so that the robot stops as
far from it whichever way the arc comes at it) decides:

- within ``stop_distance`` of the robot's edge: STOP, v := 0;
- within ``slowdown_distance``: SLOW, v := v * ``slowdown_factor``;
- else CLEAR, v unchanged.

w is kept (a round robot turning in place sweeps nothing new), unless a point lies within the robot's own
footprint grown by ``margin``: then v := 0 and w := 0 (something touches the robot or sits on the sensor).
Nothing is remembered between calls: one scan, one decision; a point beside the swept path never stops
the robot. The footprint is a disc of ``radius`` (our simulated robot; for another shape give the radius of
the circle that encloses it), grown by ``margin``; distances are measured from that grown disc, so a
stop at ``stop_distance`` leaves at least ``stop_distance + margin`` to the robot itself.

``min_points`` (Nav2's ``min_points``) makes a zone count as occupied only when that many points lie in
it, so that one spurious return does not stop a robot; 1 (the default) trusts every point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from vtr.runtime.contracts import ROBOT_RADIUS
from vtr.runtime.scan import Scan

#: Zones, from the most to the least restrictive; NO_SCAN: no reading, the command passes unchanged.
STOP, SLOW, CLEAR, NO_SCAN = "stop", "slow", "clear", "no_scan"


@dataclass(frozen=True)
class SafetyConfig:
    """The robot's size and the zones ahead of it (metres unless said)."""

    radius: float = ROBOT_RADIUS  # footprint: a disc (another shape: the radius of the circle enclosing it)
    margin: float = 0.02  # added to the footprint on every side
    stop_distance: float = 0.25  # from the (grown) footprint to what is in its way
    slowdown_distance: float = 0.6
    slowdown_factor: float = 0.5  # v scale in the slowdown zone
    min_points: int = 1  # points a zone needs to count as occupied
    #: The taught route's shape ahead (``taught_zones`` sets it): after ``bend[0]`` m of travel it turns on
    #: the spot by ``bend[1]`` rad (NaN: it ends there) and drives on; the zones follow it. None: no route.
    bend: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        for name in ("radius", "margin", "stop_distance", "slowdown_distance", "slowdown_factor"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"SafetyConfig.{name} must be a finite number, got {value!r}")
        if not 0 < self.radius <= 5:
            raise ValueError(f"SafetyConfig.radius must be in (0, 5] m, got {self.radius}")
        if not 0 <= self.margin <= 1:
            raise ValueError(f"SafetyConfig.margin must be in [0, 1] m, got {self.margin}")
        if not 0 <= self.stop_distance <= self.slowdown_distance <= 10:
            raise ValueError(
                "SafetyConfig needs 0 <= stop_distance <= slowdown_distance <= 10 m, got "
                f"{self.stop_distance} and {self.slowdown_distance}"
            )
        if not 0 <= self.slowdown_factor <= 1:
            raise ValueError(f"SafetyConfig.slowdown_factor must be in [0, 1], got {self.slowdown_factor}")
        if isinstance(self.min_points, bool) or not isinstance(self.min_points, int) or self.min_points < 1:
            raise ValueError(f"SafetyConfig.min_points must be an integer >= 1, got {self.min_points!r}")


@dataclass(frozen=True)
class SafetyDecision:
    """What :func:`limit_twist` let through, and the evidence for it.

    ``distance``: how far the nearest point in the robot's way is from its grown footprint (m, 0 when one
    is already inside it); ``bearing``: that point's direction from the robot's centre (rad, REP-103).
    Both None when nothing is in the way or there is no scan. ``footprint``: a point lies within the grown footprint, so the turn was refused too.
    ``reversing``: the driving direction was backwards (v < 0), so ``distance`` is behind the robot.
    """

    v: float
    w: float
    zone: str
    commanded: tuple[float, float]  # (v, w) asked for
    distance: float | None = None
    bearing: float | None = None
    footprint: bool = False
    reversing: bool = False

    @property
    def blocked(self) -> bool:
        """The motion asked for was refused: a stop while driving, or anything in the footprint (a turn in
        place with the way ahead occupied is not blocked: it is allowed)."""
        return self.footprint or (self.zone == STOP and self.commanded[0] != 0.0)

    @property
    def limited(self) -> bool:
        return self.v != self.commanded[0] or self.w != self.commanded[1]

    def describe(self) -> str:
        """One line for logs and the run's evidence, e.g. ``blocked: obstacle 0.22 m ahead``."""
        where = "behind" if self.reversing else "ahead"
        seen = "" if self.distance is None else f"obstacle {self.distance:.2f} m {where}"
        if self.zone == NO_SCAN:
            return "no range scan: camera-only safety"
        if self.footprint:
            return f"blocked: something within the robot's footprint{', ' + seen if seen else ''}"
        if self.zone == STOP:
            return f"blocked: {seen}" if self.blocked else f"way {where} blocked: {seen}"
        if self.zone == SLOW:
            return f"slowing down: {seen}"
        return f"clear: {seen}" if seen else f"clear {where}"


def scan_points(scan: Scan) -> np.ndarray:
    """(2, n) robot-frame points (row 0 x forward, row 1 y left, metres from the robot's centre) of the
    beams that saw something."""
    seen = scan.ranges < np.inf
    pts = scan.directions()[:, seen] * scan.ranges[seen]
    pts[0] += scan.x_m
    return pts


#: Arcs flatter than this radius (m) are driven as straight lines.
STRAIGHT_RADIUS = 1e3


def swept_gaps(x: np.ndarray, y: np.ndarray, v: float, w: float, reach: float) -> np.ndarray:
    """(n,) how far (m, along its path) a disc of radius ``reach`` driven forward from the origin on the arc
    of (v > 0, w) travels before it touches each point (x ahead, y left); inf for points it never meets
    within half a turn, 0 for those it touches already."""
    radius = v / w if w else math.inf
    if abs(radius) > STRAIGHT_RADIUS:  # a straight corridor as wide as the disc
        y2 = y * y
        with np.errstate(invalid="ignore"):
            gaps = x - np.sqrt(reach * reach - y2)
        return np.where((y2 <= reach * reach) & (x > 0), np.maximum(gaps, 0.0), np.inf)
    # the centre moves on a circle about (0, radius): a point at rho from that centre is touched once the
    # angle between it and the robot (about the centre) is at most a, with cos a = q
    r = abs(radius)
    rho = np.hypot(x, y - radius)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = (rho * rho + r * r - reach * reach) / (2 * rho * r)
    psi = np.arctan2(y - radius, x)
    ahead = np.mod(psi + math.pi / 2 if radius > 0 else math.pi / 2 - psi, 2 * math.pi)  # angle to travel
    a = np.arccos(np.clip(q, -1.0, 1.0))
    gaps = r * np.maximum(ahead - a, 0.0)
    gaps[(ahead > 2 * math.pi - a) | (q <= -1)] = 0.0  # within the disc already
    gaps[(q > 1) | (ahead - a > math.pi) | ~np.isfinite(q)] = np.inf
    return gaps


def _bent(
    gaps: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    v: float,
    w: float,
    reach: float,
    travel: float,
    turn: float,
) -> np.ndarray:
    """``gaps`` along the commanded arc up to ``travel`` m, then straight on along the heading the route takes
    after turning ``turn`` rad on the spot there (nothing past the route's end, ``turn`` NaN)."""
    first = np.where(gaps <= travel, gaps, np.inf)
    if not math.isfinite(turn):
        return first
    radius = v / w if w else math.inf
    if abs(radius) > STRAIGHT_RADIUS:
        px, py, heading = travel, 0.0, 0.0
    else:
        a = travel / abs(radius)
        px, py, heading = abs(radius) * math.sin(a), radius * (1 - math.cos(a)), math.copysign(a, radius)
    c, s = math.cos(heading + turn), math.sin(heading + turn)
    dx, dy = x - px, y - py
    then = swept_gaps(c * dx + s * dy, -s * dx + c * dy, 1.0, 0.0, reach) + travel
    return np.minimum(first, then)


def limit_twist(v: float, w: float, scan: Scan | None, cfg: SafetyConfig = SafetyConfig()) -> SafetyDecision:
    """The twist the robot may drive now, given the latest scan (None: unchanged, zone NO_SCAN)."""
    reversing = v < 0
    if scan is None:
        return SafetyDecision(v, w, NO_SCAN, (v, w), reversing=reversing)
    x, y = scan_points(scan)
    if reversing:
        x, w = -x, -w  # along the driving direction (mirrored, the turn's sense flips)
    reach = cfg.radius + cfg.margin
    k = cfg.min_points
    footprint = int(np.count_nonzero(x * x + y * y < reach * reach)) >= k
    # The zone: the points the grown disc meets as it drives on along the commanded arc (straight ahead when
    # the robot stands or turns in place); the gap is how far it drives before it touches one.
    gaps = swept_gaps(x, y, abs(v), w if v else 0.0, reach)
    if cfg.bend is not None and not reversing:
        gaps = _bent(gaps, x, y, abs(v), w if v else 0.0, reach, *cfg.bend)
    ahead = gaps <= cfg.slowdown_distance  # in the way within the zones' travel (inf: never)
    distance = bearing = None
    zone, v_out = CLEAR, v
    if ahead.any():
        xa, ya = x[ahead], y[ahead]
        # how near each point in the way is, straight (never more than the travel to it): the robot stops
        # stop_distance short of it, whichever way the arc comes at it
        gaps = np.maximum(np.hypot(xa, ya) - reach, 0.0)
        nearest = int(np.argmin(gaps))
        distance = float(gaps[nearest])
        bearing = math.atan2(float(ya[nearest]), -float(xa[nearest]) if reversing else float(xa[nearest]))
        deciding = float(np.partition(gaps, k - 1)[k - 1]) if gaps.size >= k else math.inf
        if deciding <= cfg.stop_distance:
            zone, v_out = STOP, 0.0
        elif deciding <= cfg.slowdown_distance:
            zone, v_out = SLOW, v * cfg.slowdown_factor
    if footprint:
        return SafetyDecision(0.0, 0.0, STOP, (v, w), distance, bearing, True, reversing)
    return SafetyDecision(v_out, w, zone, (v, w), distance, bearing, False, reversing)


#: The repeat's zones stay this much (m) short of the free distance the teach's scan showed at a subgoal.
CLEARANCE_SLACK = 0.05


def travel_ahead(poses: np.ndarray | None) -> tuple[np.ndarray, np.ndarray] | None:
    """(L,) the taught travel (m) from each subgoal to where the route next stops translating, a turn in
    place (a gap without translation where the heading changes) or the route's end, and (L,) that turn's
    angle (rad; NaN: the route ends there); None without poses."""
    if poses is None or len(poses) < 2 or not np.isfinite(poses).all():
        return None
    gaps = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    turned = np.remainder(np.diff(poses[:, 2]) + math.pi, 2 * math.pi) - math.pi
    stops = (gaps < 1e-3) & (np.abs(turned) > 1e-3)
    travel, turn = np.zeros(len(poses)), np.full(len(poses), np.nan)
    for i in range(
        len(poses) - 2, -1, -1
    ):  # from the end: 0 at a turn's start, else the next one's + the gap
        if stops[i]:
            travel[i] = 0.0
            turn[i] = turned[i] + (turn[i + 1] if i + 1 < len(stops) and stops[i + 1] else 0.0)  # all of it
        else:
            travel[i], turn[i] = travel[i + 1] + gaps[i], turn[i + 1]
    return travel, turn


def taught_zones(
    cfg: SafetyConfig,
    clearance: np.ndarray | None,
    target: int,
    ahead: tuple[np.ndarray, np.ndarray] | None = None,
) -> SafetyConfig:
    """The zones toward subgoal ``target`` of a route taught with ``clearance`` (``Route.clearance``): never
    longer than the free distance the teach drove up to there, less CLEARANCE_SLACK, so that a route taught
    close to a counter or a wall can be repeated while anything new in the way still stops the robot; and,
    given the route's :func:`travel_ahead`, bent where the route turns in place (``SafetyConfig.bend``): what
    stands beside the leg after a turn, straight ahead of the robot driving to it, is not in the way, what
    stands on that leg is."""
    if ahead is not None and len(ahead[0]):
        i = max(0, min(target - 1, len(ahead[0]) - 1))
        cfg = replace(cfg, bend=(float(ahead[0][i]), float(ahead[1][i])))
    if clearance is None:
        return cfg
    near = clearance[max(0, target - 1) : target + 1]
    near = near[np.isfinite(near)]
    if near.size == 0 or float(near.min()) - CLEARANCE_SLACK >= cfg.slowdown_distance:
        return cfg
    free = max(0.0, float(near.min()) - CLEARANCE_SLACK)
    stop = min(cfg.stop_distance, free)
    return replace(cfg, stop_distance=stop, slowdown_distance=max(stop, min(cfg.slowdown_distance, free)))
