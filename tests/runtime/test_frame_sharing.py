"""A frame's derived data is made once per step and shared by the stages that need it (issue 19's step
budget): its planar levels (the matcher, light matching, the policy), its pooled sums (the localiser's
matcher and the obstruction detector) and its patch features (the localiser, and anyone asking again)."""

from __future__ import annotations

import numpy as np
import pytest
from floor_fakes import box_at, floor_view, straight_route

from vtr.runtime import frame as frame_module
from vtr.runtime import matching
from vtr.runtime.follower import Follower
from vtr.runtime.frame import Frame, as_frame
from vtr.runtime.light import LightMatchedPolicy
from vtr.runtime.matching import Matcher
from vtr.runtime.route import Route


class Counting:
    """Wraps a function, keeping the first argument and the result of each call."""

    def __init__(self, call):
        self.call, self.args, self.results = call, [], []

    def __call__(self, *args, **kwargs):
        self.args.append(args[0])
        self.results.append(self.call(*args, **kwargs))
        return self.results[-1]

    def calls_on(self, array: np.ndarray) -> int:
        return sum(a is array for a in self.args)


class LevelsPolicy:
    """Reads the frame's levels as OnnxPolicy does, and drives on."""

    image_shape = (128, 128)

    def predict(self, current, subgoal):
        assert as_frame(current).levels.shape == (3, 128, 128)
        return np.array([[0.2, 0.2], [0.0, 0.0]], dtype=np.float32)


#: A far wall of random texture above the horizon (the floor world's sky is plain grey, which the
#: controller would judge by the raw error, as for any too-plain route).
WALL = np.random.default_rng(5).integers(0, 256, (64, 128, 3)).astype(np.uint8)


def view(x: float) -> np.ndarray:
    image = floor_view(x)
    image[:64] = np.roll(WALL, int(40 * x), axis=1)  # the wall slides a little as the robot drives
    return image


def follower() -> Follower:
    _, poses = straight_route(12, 0.1)
    views = np.stack([view(x) for x, _, _ in poses])
    commands = np.zeros((12, 2))
    commands[:-1, 0] = 0.25
    route = Route(images=views, poses=poses, commands=commands, name="floor", dt=0.1)
    f = Follower.for_route(route)
    assert f.obstruction is not None and f.matcher.cfg.method == "patch"
    return f


@pytest.fixture
def counted(monkeypatch):
    counts = {
        "planar": Counting(frame_module.planar),
        "pool": Counting(matching.pool),
        "moments": Counting(lambda frame, make: make(frame)),
    }
    monkeypatch.setattr(frame_module, "planar", counts["planar"])
    monkeypatch.setattr(matching, "pool", counts["pool"])
    make = Matcher._frame_moments
    monkeypatch.setattr(
        Matcher, "_frame_moments", lambda self, frame: counts["moments"](frame, lambda fr: make(self, fr))
    )
    return counts


@pytest.mark.parametrize("x", [0.31, 0.55])
def test_one_step_makes_each_frames_levels_pooled_sums_and_features_once(counted, x):
    f = follower()
    policy = LightMatchedPolicy(LevelsPolicy())
    image = box_at(view(x), 0.5) if x > 0.5 else view(x)
    for counter in counted.values():  # the route's own features and levels were made with the follower
        counter.args.clear()
        counter.results.clear()
    frame = Frame.decoded(image)
    bands = f.obstruction.floor.pool = Counting(f.obstruction.floor.pool)
    f.commanded(0.25, 0.0, 0.1)
    f.judge(frame)  # the localiser's features, then the obstruction detector on the same frame
    policy.predict(frame, f.subgoals[f.index])  # light matching and the policy read the frame's levels
    assert f.matcher.features(frame) is f.matcher.features(frame)  # kept on the frame, not made again
    assert counted["planar"].calls_on(image) == 1
    assert counted["pool"].calls_on(frame.levels) == 1  # shared by the localiser's matcher and the detector
    # the detector pools no band of this frame: its tiles' features come from the tile moments the localiser's
    # matcher made (centred values and spreads, made once per frame; only the floor on the spread differs)
    assert bands.calls_on(frame) == 0
    assert counted["moments"].calls_on(frame) == 1
    assert not f.matcher.features(frame).flags.writeable


def test_the_detector_pools_a_frame_as_it_pools_the_same_image():
    f = follower()
    image = view(0.42)
    floor = f.obstruction.floor
    shared, own = floor.pool(Frame.decoded(image)), floor.pool(image)
    assert shared.dtype == own.dtype and np.array_equal(shared, own)
    features = f.matcher.features(Frame.decoded(image))
    assert np.array_equal(features, f.matcher.features(image[None])[0])


@pytest.mark.parametrize("x", [0.2, 0.42, 0.77])
def test_the_detectors_tile_features_from_the_shared_moments_are_its_own_bits(x):
    """The detector's features of a frame's tiles, from the localiser's tile moments, equal those it makes
    from the pooled band itself (each tile normalised on its own; only the floor on the spread differs)."""
    f = follower()
    floor = f.obstruction.floor
    image = box_at(view(x), 0.5)
    frame = Frame.decoded(image)
    f.matcher.features(frame)  # the localiser's matcher makes the moments first, as in the step
    which = np.arange(len(floor.tiles))
    shared = floor.frame_features(frame, which)
    assert floor.matcher.cfg.std_floor != f.matcher.cfg.std_floor
    assert shared.dtype == np.float32 and np.array_equal(shared, floor.features(floor.pool(image), which))
    assert np.array_equal(floor.frame_features(frame, which[::3]), shared[::3])


def test_distances_over_a_window_are_the_trimmed_means_of_the_per_tile_differences():
    m = Matcher()
    views, _ = straight_route(9, 0.1)
    feats = m.features(views)
    one = m.features(Frame.decoded(floor_view(0.13)))
    first = m.distances(one, feats)
    again = m.distances(one, feats[2:7])
    assert np.array_equal(again, first[2:7])
    diff = np.abs(feats - one)
    per_tile = np.add.reduce(diff, axis=-1) / diff.shape[-1]
    keep = int(round(per_tile.shape[1] * 0.5))
    expected = (np.add.reduce(np.partition(per_tile, keep - 1, axis=1)[:, :keep], axis=1) / keep).astype(
        np.float64
    )
    assert np.array_equal(first, expected)
    assert np.array_equal(m.tile_distances(one, feats[:2]), per_tile[:2])
