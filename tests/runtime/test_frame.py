"""runtime.frame: a camera frame checked once where it enters, and never again downstream."""

from __future__ import annotations

import numpy as np
import pytest
from runtime_fakes import FakeSim, build_velocitynet_onnx, corridor_route, render

from vtr.runtime import frame as frame_module
from vtr.runtime import protocol
from vtr.runtime.client import SimClient
from vtr.runtime.contracts import Observation
from vtr.runtime.frame import Frame, as_frame, check_image, frames_of
from vtr.runtime.light import LightMatchedPolicy
from vtr.runtime.policy import OnnxPolicy
from vtr.runtime.protocol import BadFrameError
from vtr.runtime.repeater import RepeatConfig, Repeater


def test_an_array_is_checked_copied_and_made_read_only_and_a_frame_passes_as_it_is():
    image = render(0.1)
    frame = as_frame(image)
    assert isinstance(frame, Frame) and frame.shape == image.shape and np.array_equal(frame.image, image)
    assert not frame.image.flags.writeable and not np.shares_memory(frame.image, image)
    image[:] = 0  # the frame owns its pixels
    assert frame.image.any() and as_frame(frame) is frame and as_frame(frame, (99, 99)) is frame
    assert np.asarray(frame) is frame.image
    handed = render(0.2)
    given = as_frame(handed, copy=False)  # the caller hands the array over: read-only, not copied
    assert given.image is handed and not handed.flags.writeable


def test_the_levels_and_what_is_derived_are_made_once_and_kept_on_the_frame():
    frame = as_frame(np.random.default_rng(0).integers(0, 256, (4, 6, 3), dtype=np.uint8))
    levels = frame.levels
    assert levels is frame.levels and levels.dtype == np.float32 and not levels.flags.writeable
    assert np.array_equal(levels, frame.image.transpose(2, 0, 1)) and levels.flags.c_contiguous
    made = []
    first = frame.derived("key", lambda f: made.append(f) or levels.sum())
    assert frame.derived("key", lambda f: made.append(f)) == first and made == [frame]


def test_a_frame_given_by_its_levels_has_the_image_of_those_levels():
    image = np.random.default_rng(1).integers(0, 256, (4, 6, 3), dtype=np.uint8)
    levels = image.transpose(2, 0, 1).astype(np.float32)
    frame = Frame.from_levels(levels)
    assert frame.levels is levels and not levels.flags.writeable and frame.shape == (4, 6, 3)
    assert np.array_equal(frame.image, image) and not frame.image.flags.writeable


@pytest.mark.parametrize(
    "bad, words",
    [
        (np.zeros((4, 6, 3), np.float32), "float32"),
        (np.zeros((4, 6), np.uint8), r"\(4, 6\) uint8"),
        (np.zeros((4, 6, 4), np.uint8), r"\(4, 6, 4\) uint8"),
        ([[0, 0, 0]], "list"),
        (np.zeros((5, 6, 3), np.uint8), r"image \(5, 6, 3\) uint8, expected \(4, 6, 3\) uint8"),
    ],
)
def test_a_bad_image_is_one_clear_error_naming_what_it_is(bad, words):
    with pytest.raises(BadFrameError, match=words) as err:
        as_frame(bad, (4, 6))
    assert "\n" not in str(err.value)


def test_frames_of_a_route_are_one_read_only_copy_per_subgoal():
    images = corridor_route().images
    frames = frames_of(images)
    assert len(frames) == len(images) and all(
        np.array_equal(f.image, i) for f, i in zip(frames, images, strict=True)
    )
    assert not any(np.shares_memory(f.image, images) for f in frames)


class WireRobot:
    """The corridor robot behind the real wire codec: each frame is encoded as a server would, decoded by
    ``protocol.decode_reply`` and made an observation by ``SimClient``; ``truncate`` cuts these calls' pixels."""

    def __init__(self, truncate: set[int] = frozenset()) -> None:
        self.sim, self.truncate, self.calls = FakeSim(), set(truncate), 0

    def _reply(self, cmd: str, image: np.ndarray) -> Observation:
        self.calls += 1
        header, pixels = protocol.encode_image_reply(cmd, 1, "s", float(self.sim.time), image)
        if self.calls in self.truncate:
            pixels = pixels[:-1]
        reply = protocol.decode_reply([header, pixels], expect_cmd=cmd, expect_seq=1, expect_shape=(16, 16))
        return SimClient._observation(reply)

    def observe(self) -> Observation:
        return self._reply("observe", self.sim.observe())

    def step(self, v: float, w: float, duration: float) -> Observation:
        return self._reply("step", self.sim.step(v, w, duration))

    def stop(self) -> None:
        pass


def test_a_step_checks_its_frame_where_it_was_decoded_and_converts_it_once(tmp_path, monkeypatch):
    policy = LightMatchedPolicy(OnnxPolicy(build_velocitynet_onnx(str(tmp_path / "m.onnx"))))
    rep = Repeater(WireRobot(), policy, corridor_route(), config=RepeatConfig(max_steps=40))
    checks, converted = [], []
    planar = frame_module.planar
    monkeypatch.setattr(frame_module, "check_image", lambda *a, **k: checks.append(a) or check_image(*a, **k))
    monkeypatch.setattr(frame_module, "planar", lambda image: converted.append(image) or planar(image))
    records = [rep.step() for _ in range(6)]
    assert all(r.commanded for r in records)
    # the decoder checked each frame: nothing downstream (Repeater, follower, matcher, light, policy) again
    assert checks == []
    # each camera frame was converted to planar levels once, for the matcher, light matching and the policy
    cameras = [image for image in converted if not any(np.shares_memory(image, v.image) for v in rep._views)]
    assert len(cameras) == len(records) and len({id(image) for image in cameras}) == len(cameras)


def test_a_bad_frame_is_refused_by_the_decoder_with_one_error_and_never_reaches_the_step(tmp_path):
    seen = []

    class Spy(OnnxPolicy):
        def predict(self, current, subgoal):
            seen.append(current)
            return super().predict(current, subgoal)

    policy = Spy(build_velocitynet_onnx(str(tmp_path / "m.onnx")))
    robot = WireRobot(truncate={2})
    rep = Repeater(robot, policy, corridor_route(), config=RepeatConfig(max_steps=3, bad_frame_backoff_s=0.0))
    seen.clear()  # the zero bias's pass over the route
    summary = rep.run()
    assert summary.bad_frames == 1 and rep._last_rejected.startswith("truncated pixel frame")
    assert len(seen) == summary.steps == 3 and all(isinstance(f, Frame) for f in seen)
