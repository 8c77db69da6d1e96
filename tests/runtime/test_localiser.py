"""The route localiser: a Bayes filter over positions along the route, from views and commanded motion."""

from __future__ import annotations

import numpy as np
import pytest
from runtime_fakes import corridor_route, render

from vtr.runtime.kinematics import taught_motion
from vtr.runtime.localiser import LocaliserConfig, RouteLocaliser
from vtr.runtime.matching import MatchConfig, Matcher

SPACING = 0.05  # m between the corridor route's subgoals


def _localiser(length_m: float = 0.6, **cfg) -> RouteLocaliser:
    route = corridor_route(length_m, SPACING)
    matcher = Matcher(MatchConfig.paper())
    feats = matcher.features(route.images)
    gaps = np.array([matcher.distance(feats[k], feats[k + 1]) for k in range(len(feats) - 1)])
    motion = taught_motion(route.poses, route.commands, len(route), 0.2)
    return RouteLocaliser(feats, matcher, motion, float(np.median(gaps)), LocaliserConfig(**cfg))


def _view(x: float) -> np.ndarray:
    return Matcher(MatchConfig.paper()).features(render(x))


def test_views_along_the_route_place_the_robot_between_subgoals():
    loc = _localiser()
    for x in np.arange(0.0, 0.3, 0.0125):  # a quarter of a gap per view, as commanded
        est = loc.update(_view(x))
        loc.predict(0.125, 0.0, 0.1)
    assert est.position == pytest.approx(x / SPACING, abs=0.3)
    assert est.confidence > 0.5 and est.std < 0.5


def test_commanded_motion_moves_the_estimate_by_the_taught_share_of_a_gap():
    loc = _localiser()
    loc.update(_view(0.1))  # subgoal 2
    before = loc.last.position
    loc.predict(0.25, 0.0, 0.1)  # 2.5 cm: half of a 5 cm gap
    loc.predict(0.25, 0.0, 0.1)
    assert float(loc.belief @ loc.cells) == pytest.approx(before + 1.0, abs=0.15)
    assert loc.progress(-0.25, 0.0, 0.1, 2.0) == pytest.approx(-0.5)  # backwards counts back


def test_a_command_s_travel_along_the_route_is_its_motion_projected_on_the_taught_one():
    """The end by travel (``EndWatch``) counts motion as the filter does: on a taught straight a drive counts
    its distance either way and a turn in place nothing; in a taught turn in place, the turn."""
    loc = _localiser()
    loc.update(_view(0.1))
    assert loc.travel(0.25, 0.0, 0.1) == pytest.approx(0.025)
    assert loc.travel(-0.25, 0.0, 0.1) == pytest.approx(0.025)
    assert loc.travel(0.0, 1.0, 0.1) == pytest.approx(0.0)
    assert loc.travelled[-1] == pytest.approx(0.6)
    turning = RouteLocaliser(
        loc.feats, loc.matcher, np.array([[0.0, 0.2]] * (loc.n - 1)), 1.0, LocaliserConfig(turn_length_m=0.2)
    )
    assert turning.travel(0.0, -0.5, 0.1) == pytest.approx(0.2 * 0.05)  # either way
    assert turning.travel(0.1, 0.0, 0.1) == pytest.approx(0.0)  # driving in a turn in place does not get on


def test_a_view_that_does_not_move_holds_the_estimate_whatever_is_commanded():
    """Commands say the robot drove 3 gaps; the camera keeps seeing subgoal 2: the views win."""
    loc = _localiser()
    for _ in range(6):
        loc.update(_view(0.1))
        loc.predict(0.25, 0.0, 0.1)
    est = loc.update(_view(0.1))
    assert est.position == pytest.approx(2.0, abs=0.6)


def test_started_wide_it_finds_the_robot_anywhere_on_the_route():
    loc = _localiser()
    loc.start_at(None)
    assert loc.wide and len(loc.window()) == 13
    est = loc.update(_view(0.4))
    assert est.position == pytest.approx(8.0, abs=0.5) and not loc.wide


def test_a_view_far_from_every_subgoal_matches_badly():
    loc = _localiser()
    good = loc.update(_view(0.1)).best_error
    bad = loc.update(_view(0.95)).best_error  # far beyond the route's end
    assert bad > 10 * max(good, 1.0)


def test_settings_are_checked_where_they_enter():
    with pytest.raises(ValueError, match="cells_per_gap"):
        LocaliserConfig(cells_per_gap=0)
    with pytest.raises(ValueError, match="obs_sigma"):
        LocaliserConfig(obs_sigma=float("nan"))


def test_a_move_keeps_the_belief_where_the_route_is_and_piles_only_what_passes_an_end():
    """At the start of a route half the belief sits on the first cells: a move forward must carry it along,
    not lose it at the start and pile it at the end (a plain room's route 'finished' after 2 commands)."""
    loc = _localiser()
    before = float(loc.belief @ loc.cells)  # a half-normal at the first subgoal: mean 0.2 gaps
    loc.predict(0.15, 0.0, 0.1)  # 0.3 gap (1.2 cells) forward from the start
    assert loc.belief.sum() == pytest.approx(1.0)
    assert loc.belief[-4:].sum() < 1e-3
    assert float(loc.belief @ loc.cells) == pytest.approx(before + 0.3, abs=0.1)
    loc.start_at(12.0)  # the last subgoal: a move forward stays there
    loc.predict(0.25, 0.0, 0.1)
    assert float(loc.belief @ loc.cells) == pytest.approx(12.0, abs=0.15)


def test_a_frame_is_weighed_as_its_features_are():
    from vtr.runtime.frame import as_frame

    by_frame, by_features = _localiser(), _localiser()
    for x in (0.1, 0.1125, 0.125):
        a, b = by_frame.update(as_frame(render(x))), by_features.update(_view(x))
        assert (a.position, a.confidence, a.best) == (b.position, b.confidence, b.best)
        assert np.array_equal(a.errors, b.errors)


def _textured_localiser(turn: float = 0.0, **cfg) -> tuple[RouteLocaliser, np.ndarray]:
    """A route of 12 unrelated textured views, matched patch by patch (the default matcher), taught driving
    0.1 m and turning ``turn`` rad a gap."""
    images = np.random.default_rng(11).integers(0, 256, (12, 64, 64, 3), dtype=np.uint8)
    matcher = Matcher(MatchConfig())
    feats = matcher.features(images)
    poses = np.stack([np.arange(12) * 0.1, np.zeros(12), np.arange(12) * turn], axis=1)
    motion = taught_motion(poses, np.tile([0.25, 0.0], (12, 1)), 12, 0.4)
    return RouteLocaliser(feats, matcher, motion, 1.0, LocaliserConfig(**cfg)), images


@pytest.mark.parametrize("pixels", [12, -12, 6])
def test_a_view_turned_off_the_taught_heading_still_matches_its_subgoal(pixels):
    """Turned a few degrees, the view is the taught one moved sideways: unshifted it matches nothing (a
    robot correcting a side offset got lost this way, dev routes), registered it matches its subgoal."""
    from vtr.runtime.frame import as_frame

    loc, images = _textured_localiser()
    loc.start_at(5.0)
    turned = as_frame(np.roll(images[5], pixels, axis=1))
    est = loc.update(turned)
    assert est.best == 5 and est.best_error < 0.05
    assert est.position == pytest.approx(5.0, abs=0.3)
    blind, _ = _textured_localiser(shifts=())
    blind.start_at(5.0)
    assert blind.update(turned).best_error > 0.8


def test_where_the_teach_turned_a_sideways_shift_is_not_registered():
    """In a taught turn the neighbouring subgoals are the view shifted sideways: heading is position there,
    and registering it away let a robot turn past a taught turn in place's end (dev gen_105)."""
    from vtr.runtime.frame import as_frame

    loc, images = _textured_localiser(turn=0.2)
    loc.start_at(5.0)
    assert loc.update(as_frame(np.roll(images[5], 12, axis=1))).best_error > 0.8
    with pytest.raises(ValueError, match="shifts"):
        LocaliserConfig(shifts=(0,))
    with pytest.raises(ValueError, match="under the tile side"):
        _textured_localiser(shifts=(8,))
