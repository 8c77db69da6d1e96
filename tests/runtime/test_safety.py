"""The range-scan safety layer: stop and slowdown zones in the driving direction, nothing else."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from vtr.runtime.safety import CLEAR, NO_SCAN, SLOW, STOP, SafetyConfig, limit_twist, scan_points
from vtr.runtime.scan import Scan

CFG = SafetyConfig()  # radius 0.17 + margin 0.02: the grown footprint has radius 0.19
GROWN = CFG.radius + CFG.margin


def scan_of(points: list[tuple[float, float]], x_m: float = 0.0, beams: int = 720) -> Scan:
    """A 360 deg scan (0.5 deg beams) that sees exactly ``points`` (robot frame), nothing else."""
    inc = 2 * math.pi / beams
    ranges = np.full(beams, np.inf, dtype=np.float32)
    for x, y in points:
        dx = x - x_m
        i = round((math.atan2(y, dx) + math.pi) / inc) % beams
        ranges[i] = math.hypot(dx, y)
    return Scan(-math.pi, inc, 10.0, ranges, x_m)


def ahead(gap: float, y: float = 0.0) -> tuple[float, float]:
    """The point a gap of ``gap`` m in front of the grown footprint, at lateral offset y."""
    return (gap + math.sqrt(GROWN**2 - y**2), y)


def test_no_scan_passes_the_command_unchanged():
    d = limit_twist(0.3, 0.2, None)
    assert (d.v, d.w, d.zone, d.distance) == (0.3, 0.2, NO_SCAN, None)
    assert not d.blocked and "camera-only" in d.describe()


def test_nothing_seen_is_clear():
    d = limit_twist(0.3, 0.2, scan_of([]))
    assert (d.v, d.w, d.zone, d.distance, d.bearing) == (0.3, 0.2, CLEAR, None, None)
    assert not d.limited


@pytest.mark.parametrize(
    ("gap", "zone", "v"),
    [(0.01, STOP, 0.0), (0.2, STOP, 0.0), (0.4, SLOW, 0.15), (1.0, CLEAR, 0.3)],
)
def test_a_point_ahead_stops_slows_or_not_by_its_distance(gap, zone, v):
    d = limit_twist(0.3, 0.02, scan_of([ahead(gap)]))
    assert d.zone == zone and d.v == pytest.approx(v)
    assert d.w == 0.02  # the turn is kept
    if gap > CFG.slowdown_distance:  # beyond the zones' reach: not in the way
        assert d.distance is None and d.bearing is None
    else:
        assert d.distance == pytest.approx(gap, abs=0.01) and d.bearing == pytest.approx(0.0, abs=0.01)


def test_the_zone_follows_the_commanded_arc():
    """The disc swept along the arc of (v, w): what the robot turns toward stops it, what it turns away
    from does not; the distance is straight from the grown footprint (the travel to it is longer)."""
    left = (0.35, 0.35)  # 0.49 m away, 45 degrees to the left: beside the straight corridor
    assert limit_twist(0.3, 0.0, scan_of([left])).zone == CLEAR
    # on a 0.35 m radius arc to the left the centre passes that point: touched after a short stretch
    turning = limit_twist(0.3, 0.3 / 0.35, scan_of([left]))
    straight = math.hypot(0.35, 0.35) - GROWN
    along = 0.35 * (math.pi / 2 - 2 * math.asin(GROWN / 0.7))  # a quarter turn, less the chord it touches at
    assert turning.zone == SLOW and turning.distance == pytest.approx(straight) and straight < along
    assert limit_twist(0.3, -0.3 / 0.35, scan_of([left])).zone == CLEAR  # turning away to the right
    # a straight-ahead point the arc curves away from: clear, though the straight corridor held it
    assert limit_twist(0.3, 1.0, scan_of([ahead(0.3)])).distance is None
    assert limit_twist(0.3, 0.0, scan_of([ahead(0.3)])).zone == SLOW
    # reversing on an arc: mirrored
    back = limit_twist(-0.3, 0.3 / 0.35, scan_of([(-0.35, -0.35)]))  # backwards, the ICR on the right
    assert back.zone == SLOW and back.reversing and back.distance == pytest.approx(straight)


def test_the_evidence_names_the_distance():
    d = limit_twist(0.3, 0.0, scan_of([ahead(0.22)]))
    assert d.blocked and d.describe() == "blocked: obstacle 0.22 m ahead"
    assert limit_twist(0.3, 0.0, scan_of([ahead(0.5)])).describe() == "slowing down: obstacle 0.50 m ahead"


def test_the_corridor_is_the_robots_width_plus_margin():
    inside, outside = GROWN - 0.005, GROWN + 0.005
    assert limit_twist(0.3, 0.0, scan_of([(0.2, inside)])).zone == STOP
    assert limit_twist(0.3, 0.0, scan_of([(0.2, -inside)])).zone == STOP
    beside = limit_twist(0.3, 0.0, scan_of([(0.2, outside), (0.3, -outside)]))
    assert (beside.zone, beside.v, beside.distance) == (CLEAR, 0.3, None)


def test_a_wall_alongside_the_path_does_not_stop_the_robot():
    wall = [(x, 0.25) for x in np.arange(-1.0, 2.0, 0.02)]  # 6 cm beside the robot, all along
    d = limit_twist(0.5, 0.0, scan_of(wall))
    assert (d.zone, d.v, d.w) == (CLEAR, 0.5, 0.0)


def test_behind_counts_only_when_reversing():
    behind = [(-0.3, 0.0)]
    assert limit_twist(0.3, 0.0, scan_of(behind)).zone == CLEAR
    d = limit_twist(-0.2, 0.0, scan_of(behind))
    assert d.zone == STOP and d.v == 0.0 and d.reversing
    assert d.distance == pytest.approx(0.3 - GROWN, abs=0.01) and abs(d.bearing) == pytest.approx(
        math.pi, abs=0.01
    )
    assert d.describe() == f"blocked: obstacle {0.3 - GROWN:.2f} m behind"
    assert limit_twist(-0.2, 0.0, scan_of([ahead(0.1)])).zone == CLEAR  # reversing away from it


def test_a_turn_in_place_is_allowed_with_the_way_ahead_occupied():
    d = limit_twist(0.0, 0.8, scan_of([ahead(0.05)]))
    assert (d.v, d.w, d.zone) == (0.0, 0.8, STOP)
    assert not d.blocked and not d.limited and d.describe().startswith("way ahead blocked")


def test_a_point_within_the_footprint_refuses_the_turn_too():
    d = limit_twist(0.0, 0.8, scan_of([(-0.05, 0.15)]))  # inside the grown disc, behind the centre
    assert (d.v, d.w, d.zone, d.footprint) == (0.0, 0.0, STOP, True)
    assert d.blocked and "footprint" in d.describe()


def test_the_mounting_offset_moves_the_points():
    # the same 0.40 m reading: from the centre it is 0.21 m beyond the grown footprint, from 0.15 m ahead 0.36 m
    for x_m, zone in ((0.0, STOP), (0.15, SLOW)):
        ranges = np.full(3, np.inf, dtype=np.float32)
        ranges[1] = 0.40
        d = limit_twist(0.3, 0.0, Scan(-0.1, 0.1, 5.0, ranges, x_m))
        assert d.zone == zone
    assert scan_points(Scan(-0.1, 0.1, 5.0, ranges, 0.15)) == pytest.approx(np.array([[0.55], [0.0]]))


def test_min_points_ignores_a_lone_return():
    cfg = SafetyConfig(min_points=3)
    lone = limit_twist(0.3, 0.0, scan_of([ahead(0.1)]), cfg)
    assert lone.zone == CLEAR and lone.v == 0.3 and lone.distance == pytest.approx(0.1, abs=0.01)
    three = [ahead(0.1, y) for y in (-0.05, 0.0, 0.05)]
    assert limit_twist(0.3, 0.0, scan_of(three), cfg).zone == STOP
    # two near points and a far one: the third nearest decides
    assert limit_twist(0.3, 0.0, scan_of([three[0], three[2], ahead(0.5)]), cfg).zone == SLOW


def test_the_slowdown_scales_and_zero_distances_are_allowed():
    cfg = SafetyConfig(stop_distance=0.0, slowdown_distance=0.0, slowdown_factor=0.25)
    assert limit_twist(0.3, 0.0, scan_of([ahead(0.05)]), cfg).zone == CLEAR
    slow = SafetyConfig(slowdown_factor=0.25)
    assert limit_twist(0.4, 0.0, scan_of([ahead(0.5)]), slow).v == pytest.approx(0.1)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"radius": 0.0},
        {"margin": -0.01},
        {"stop_distance": 0.7},  # beyond the slowdown distance
        {"slowdown_factor": 1.5},
        {"min_points": 0},
        {"radius": float("nan")},
        {"min_points": True},
    ],
)
def test_a_bad_config_is_refused(kwargs):
    with pytest.raises(ValueError, match="SafetyConfig"):
        SafetyConfig(**kwargs)


def test_taught_zones_never_reach_past_what_the_teach_drove_up_to():
    from vtr.runtime.safety import CLEARANCE_SLACK, taught_zones

    cfg = SafetyConfig(stop_distance=0.25, slowdown_distance=0.6)
    assert taught_zones(cfg, None, 3) is cfg  # a route taught without a scan: the configured zones
    far = np.array([2.0, 1.5, np.inf, np.nan])
    assert taught_zones(cfg, far, 2) == cfg
    near = np.array([1.0, 0.4, 0.135, 0.135])
    capped = taught_zones(cfg, near, 3)
    assert capped.stop_distance == pytest.approx(0.135 - CLEARANCE_SLACK)
    assert capped.slowdown_distance == pytest.approx(0.135 - CLEARANCE_SLACK)
    slowed = taught_zones(cfg, near, 1)  # 0.4 m free at subgoal 1: stop unchanged, slowdown shortened
    assert slowed.stop_distance == 0.25 and slowed.slowdown_distance == pytest.approx(0.35)


def test_the_zones_bend_where_the_route_turns_in_place():
    from vtr.runtime.safety import taught_zones, travel_ahead

    # 0.3 m east in 0.1 m gaps, a quarter turn to the left on the spot, 0.2 m north, a pause, 0.1 m north
    poses = np.array(
        [[0.0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [0.3, 0, 0], [0.3, 0, 0.8], [0.3, 0, 1.6], [0.3, 0.1, 1.6]]
    )
    poses = np.vstack([poses, [[0.3, 0.2, 1.6], [0.3, 0.2, 1.6], [0.3, 0.3, 1.6]]])
    travel, turn = travel_ahead(poses)
    assert travel == pytest.approx([0.3, 0.2, 0.1, 0.0, 0.0, 0.3, 0.2, 0.1, 0.1, 0.0])
    assert turn[:5] == pytest.approx([1.6, 1.6, 1.6, 1.6, 0.8]) and np.isnan(turn[5:]).all()
    assert travel_ahead(None) is None
    cfg = SafetyConfig(stop_distance=0.25, slowdown_distance=0.6)
    to_turn = taught_zones(cfg, None, 2, (travel, turn))  # steering to subgoal 2: 0.2 m to the turn
    assert to_turn.bend == pytest.approx((0.2, 1.6)) and to_turn.stop_distance == 0.25
    # straight ahead of the robot past the turn point, beside the leg after it: not in the way ...
    assert limit_twist(0.3, 0.0, scan_of([(0.2 + 0.4, 0.0)]), to_turn).zone == CLEAR
    assert limit_twist(0.3, 0.0, scan_of([(0.2 + 0.4, 0.0)]), cfg).zone == SLOW  # (the straight zone)
    # ... on that leg, 0.3 m past the footprint at the turn point: in the way (0.34 m from the robot)
    on_leg = limit_twist(0.3, 0.0, scan_of([(0.2, GROWN + 0.3)]), to_turn)
    assert on_leg.zone == SLOW and on_leg.distance == pytest.approx(
        math.hypot(0.2, GROWN + 0.3) - GROWN, abs=0.01
    )
    # before the turn, as without a route; past the route's end, nothing
    assert limit_twist(0.3, 0.0, scan_of([ahead(0.15)]), to_turn).zone == STOP
    assert limit_twist(0.3, 0.0, scan_of([ahead(0.15)]), replace(cfg, bend=(0.1, math.nan))).zone == CLEAR


def test_what_the_arc_reaches_only_after_the_zones_travel_is_not_in_the_way():
    """Dev gen_192, box beside the path: a tight arc (0.34 m radius) bent 2.25 m on came back round past the
    box, 0.15 m from the robot; only what the robot meets within the slowdown distance's travel counts."""
    tight = (0.3, 0.3 / 0.34)
    top = (0.0, 0.68)  # half a turn round the arc: 0.49 m away, over 0.8 m of travel
    assert limit_twist(*tight, scan_of([top])).zone == CLEAR
    bent = SafetyConfig(bend=(2.25, -1.02))
    assert limit_twist(*tight, scan_of([(0.21, -0.27)]), bent).zone == CLEAR
    assert limit_twist(*tight, scan_of([(0.21, 0.1)]), bent).zone == STOP  # on the arc, 0.04 m away
