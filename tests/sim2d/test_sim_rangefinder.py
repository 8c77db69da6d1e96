"""The simulator's range scanner: the camera's rays, all around, against walls, furniture and obstacles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtr.runtime.safety import STOP, limit_twist
from vtr.sim2d import SimConfig, Simulator
from vtr.sim2d.config import RangefinderConfig
from vtr.sim2d.house import load_house
from vtr.sim2d.local_robot import LocalRobot
from vtr.sim2d.rangefinder import Rangefinder, scan_spec

START = (2.8, 3.0, 0.0)  # the paper house's living-room start, facing +x


def test_the_default_scanner_is_181_beams_over_270_degrees_centred_ahead():
    spec = scan_spec(RangefinderConfig())
    assert (spec.beams, spec.range_max, spec.x_m) == (181, 5.0, 0.1)
    assert spec.angle_min == pytest.approx(-math.radians(135))
    assert spec.angle_increment == pytest.approx(math.radians(1.5))
    full = scan_spec(RangefinderConfig(beams=360, fov_deg=360.0))
    assert full.angle_min == pytest.approx(-math.pi) and full.angle_increment == pytest.approx(
        math.radians(1)
    )


def test_straight_ahead_it_measures_the_wall_and_a_box_placed_before_it():
    house = load_house("house")
    beam = 90  # straight ahead
    assert Rangefinder(house).ranges(*START)[beam] == pytest.approx(3.05, abs=1e-3)  # wall face at x = 5.95
    boxed = load_house("house", ("obstacle:4.0,3.0=0.4",))  # front face at x = 3.8
    ranges = Rangefinder(boxed).ranges(*START)
    assert ranges[beam] == pytest.approx(3.8 - 2.9, abs=1e-3)
    assert ranges[0] == pytest.approx(Rangefinder(house).ranges(*START)[0])  # behind-right: unchanged


def test_the_nearest_return_all_around_is_the_clearance():
    house = load_house("house")
    rf = Rangefinder(house, RangefinderConfig(beams=720, fov_deg=360.0, x_m=0.0))
    rng = np.random.default_rng(3)
    x0, y0, x1, y1 = house.bounds
    checked = 0
    while checked < 30:
        x, y = rng.uniform(x0, x1), rng.uniform(y0, y1)
        clearance = house.clearance(x, y)
        if not house.is_free(x, y, 0.2) or clearance > 4.0:
            continue
        # circles are seen as the enclosing polygon the camera draws (up to ~1 cm outside); 0.5 deg beams
        assert float(rf.ranges(x, y, rng.uniform(-3, 3)).min()) == pytest.approx(clearance, abs=0.015)
        checked += 1


def test_turning_the_robot_turns_the_scan_and_far_beams_see_nothing():
    rf = Rangefinder(load_house("house"), RangefinderConfig(beams=360, fov_deg=360.0, x_m=0.0, range_max=1.5))
    a = rf.ranges(*START)
    b = rf.ranges(START[0], START[1], math.radians(10))
    np.testing.assert_allclose(np.roll(b, 10), a, atol=2e-3)
    assert np.isinf(a).any() and np.all(a[np.isfinite(a)] <= 1.5)


def test_the_scanner_is_built_on_first_use_and_mounted_inside_the_robot():
    sim = Simulator(SimConfig())
    assert sim._rangefinder is None
    assert sim.scan().beams == 181 and sim._rangefinder is not None
    with pytest.raises(ValueError, match="inside the robot"):
        SimConfig(rangefinder=RangefinderConfig(x_m=0.2))
    with pytest.raises(ValueError, match="beams"):
        RangefinderConfig(beams=0)
    with pytest.raises(ValueError, match="fov_deg"):
        RangefinderConfig(fov_deg=400.0)


def test_local_robot_adds_the_scan_only_when_asked():
    sim = Simulator(SimConfig())
    assert LocalRobot(sim).reset(pose=START).scan is None
    obs = LocalRobot(sim, scan=True).reset(pose=START)
    assert obs.scan is not None and obs.scan.x_m == 0.1 and obs.scan.beams == 181


def test_driving_at_a_box_with_the_safety_layer_stops_short_of_it():
    """The issue's case, closed loop: full speed at a 0.25 m box, the range scan stops the robot >= 0.2 m
    before it, without contact; without the layer the same commands hit it."""
    change = ("obstacle:4.2,3.0=0.25",)  # front face at x = 4.075
    robot = LocalRobot(Simulator(SimConfig(changes=change)), scan=True)
    obs = robot.reset(pose=START)
    for _ in range(60):
        decision = limit_twist(0.5, 0.0, obs.scan)
        obs = robot.step(decision.v, decision.w, 0.1)
        assert not obs.collided
    assert decision.zone == STOP and decision.blocked
    gap = 4.075 - (obs.pose[0] + SimConfig().robot_radius)
    assert 0.2 <= gap <= 0.3, gap
    blind = LocalRobot(Simulator(SimConfig(changes=change)))
    blind.reset(pose=START)
    assert any(blind.step(0.5, 0.0, 0.1).collided for _ in range(60))
