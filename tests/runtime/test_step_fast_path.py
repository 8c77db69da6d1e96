"""The Repeater's fast step path decides and steers exactly as the straightforward computation does.

Fast: frames arrive as the client's decoder makes them (``Frame.decoded`` over ``bytes``), so the frame's
planar float32 levels are made once and shared by the matcher, light matching and the policy's input
tensor; the subgoal's tensor and light statistics are kept on its frame; light matching hands its planar
float32 levels to ``OnnxPolicy`` as a frame. Straightforward: plain writeable arrays (checked and
converted by the Repeater), light matching through its uint8 image, and a policy that runs ``to_nchw`` on
both images and ``session.run`` on every step. The two runs of one scripted route must give the same
decisions, errors and velocities bit for bit, switches included.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.runtime.texture_views import view
from vtr.runtime.contracts import Observation
from vtr.runtime.frame import Frame
from vtr.runtime.light import LightMatchedPolicy
from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL, OUTPUT_VELOCITIES, ModelMeta
from vtr.runtime.policy import OnnxPolicy
from vtr.runtime.preprocess import PREPROCESSINGS, to_nchw
from vtr.runtime.repeater import RepeatConfig, Repeater
from vtr.runtime.route import Route

TAUGHT_EVERY = 4  # pixels of texture between subgoals; the robot's view moves 1 pixel per step


class ScriptedRobot:
    """Shows texture views moving one pixel per command (whatever the command), as read-only frames over
    ``bytes`` (``immutable``) or as writeable arrays."""

    def __init__(self, immutable: bool) -> None:
        self.immutable, self.x = immutable, 1

    def _frame(self) -> Observation:
        image = view(self.x)
        if self.immutable:
            decoded = np.frombuffer(image.tobytes(), np.uint8).reshape(image.shape)
            return Observation.of_frame(Frame.decoded(decoded), float(self.x))
        return Observation(image=image, stamp=float(self.x))

    def observe(self) -> Observation:
        return self._frame()

    def step(self, v: float, w: float, duration: float) -> Observation:
        self.x += 1
        return self._frame()

    def stop(self) -> None:
        pass


class PlainPolicy:
    """``OnnxPolicy``'s network without its caches and buffers: ``to_nchw`` of both images, then run."""

    def __init__(self, policy: OnnxPolicy) -> None:
        self.policy, self.meta, self.image_shape = policy, policy.meta, policy.image_shape
        self.high = np.array([[policy.meta.v_max], [policy.meta.w_max]], dtype=np.float32)

    def predict(self, current: Frame, subgoal: Frame) -> np.ndarray:
        pre = self.meta.preprocessing
        feeds = {
            INPUT_CURRENT: to_nchw(np.array(current), pre),
            INPUT_SUBGOAL: to_nchw(np.array(subgoal), pre),
        }
        (raw,) = self.policy.session.run([OUTPUT_VELOCITIES], feeds)
        return np.clip(raw[0], -self.high, self.high)


def _run(model, route: Route, fast: bool, light: bool) -> list[str]:
    policy = OnnxPolicy(model) if fast else PlainPolicy(OnnxPolicy(model))
    if light:
        policy = LightMatchedPolicy(policy)
    rep = Repeater(ScriptedRobot(immutable=fast), policy, route, config=RepeatConfig(max_steps=80))
    rows = []
    while not rep.done:
        r = rep.step()
        events = tuple((e.action, e.index, e.error) for e in r.events)
        rows.append(repr((r.subgoal, r.action, events, r.error, r.v, r.w, r.status)))  # repr: nan == nan
    return rows


@pytest.mark.parametrize("light", [True, False], ids=["light", "patch"])
@pytest.mark.parametrize("preprocessing", PREPROCESSINGS)
def test_the_fast_step_path_equals_the_straightforward_one(tmp_path, preprocessing, light):
    from vtr.benchmarks.standin import make_standin_velocitynet

    meta = ModelMeta(image_height=64, image_width=64, horizon=2, preprocessing=preprocessing)
    model = make_standin_velocitynet(tmp_path / "m.onnx", meta=meta, widths=(4, 8, 8))
    images = np.stack([view(TAUGHT_EVERY * k) for k in range(12)])
    n = len(images)
    poses = np.zeros((n, 3))  # the taught travel the commands give: 0.1 m/s for TAUGHT_EVERY steps a gap
    poses[:, 0] = 0.1 * meta.dt * TAUGHT_EVERY * np.arange(n)
    route = Route(images=images, poses=poses, commands=np.full((n, 2), 0.1), name="t", dt=meta.dt)
    fast, plain = _run(model, route, True, light), _run(model, route, False, light)
    assert fast == plain
    assert fast[-1].endswith("<RepeatStatus.FINISHED: 'finished'>)") and len(fast) > 20  # followed, switching


def test_infer_reads_feeds_changed_in_place_and_takes_any_feed_session_run_takes(tmp_path):
    from vtr.benchmarks.standin import make_standin_velocitynet

    meta = ModelMeta(image_height=32, image_width=32, horizon=2)
    policy = OnnxPolicy(make_standin_velocitynet(tmp_path / "m.onnx", meta=meta, widths=(4, 8)))
    rng = np.random.default_rng(0)
    batch = rng.random((3, 3, 32, 32), dtype=np.float32)

    def plain(feeds):
        return policy.session.run([OUTPUT_VELOCITIES], feeds)[0][0]

    feeds = {INPUT_CURRENT: batch[:1].copy(), INPUT_SUBGOAL: batch[1:2].copy()}
    first = policy.infer(feeds).copy()
    assert np.array_equal(first, plain(feeds))
    feeds[INPUT_CURRENT][:] = batch[2:3]  # the same bound array, new values
    assert np.array_equal(policy.infer(feeds), plain(feeds)) and not np.array_equal(plain(feeds), first)
    odd = {INPUT_CURRENT: batch[2:3].transpose(0, 1, 3, 2), INPUT_SUBGOAL: batch[:1].astype(np.float64)}
    assert np.array_equal(policy.infer(odd), plain({k: v.astype(np.float32) for k, v in odd.items()}))
    two = {INPUT_CURRENT: batch[:2], INPUT_SUBGOAL: batch[1:]}
    assert np.array_equal(policy.infer(two), plain(two))  # a batch: session.run, first item
