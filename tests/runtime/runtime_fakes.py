"""Test doubles for the runtime: a 1-D fake simulator with the sim2d.Simulator API, and a tiny ONNX
VelocityNet built with onnx.helper (no torch).

The fake world is a corridor along x. The camera image is a horizontal brightness ramp whose offset
grows with x (value = 20 + 200 * x + column/8), so the mean abs pixel error between two views is
200 * |x1 - x2| while the view stays inside 0..255 (x in [0, 1.0]). The tiny model drives towards the
subgoal: v = 0.5 * tanh(gain * (mean(subgoal) - mean(current))), w = 0, repeated over the N horizon.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

H = W = 16


class FakePose(NamedTuple):
    x: float
    y: float
    yaw: float


def render(x: float, h: int = H, w: int = W) -> np.ndarray:
    cols = np.arange(w, dtype=np.float64) / 8.0
    row = np.clip(np.round(20.0 + 200.0 * x + cols), 0, 255).astype(np.uint8)
    return np.repeat(np.repeat(row[None, :, None], h, axis=0), 3, axis=2)


class FakeSim:
    """The sim2d.Simulator API over the corridor world. Records every call in ``calls``."""

    def __init__(self, x: float = 0.0, h: int = H, w: int = W) -> None:
        self.h, self.w = h, w
        self.pose = FakePose(x, 0.0, 0.0)
        self.time = 0.0
        self.collided = False
        self.calls: list[tuple[Any, ...]] = []

    def reset(self, pose: Any = None, seed: int | None = None) -> np.ndarray:
        self.calls.append(("reset", pose, seed))
        self.pose = FakePose(0.0, 0.0, 0.0) if pose is None else FakePose(pose.x, pose.y, pose.yaw)
        self.time = 0.0
        return self.observe()

    def observe(self) -> np.ndarray:
        return render(self.pose.x, self.h, self.w)

    def step(self, v: float, w: float, duration: float) -> np.ndarray:
        self.calls.append(("step", v, w, duration))
        v = max(-0.5, min(0.5, v))
        x = self.pose.x + v * duration * math.cos(self.pose.yaw)
        self.pose = FakePose(x, self.pose.y, self.pose.yaw + w * duration)
        self.time += duration
        return self.observe()

    def info(self) -> dict[str, Any]:
        return {
            "camera": {"width": self.w, "height": self.h, "fov_deg": 90.0},
            "limits": {"v_max": 0.5, "w_max": 1.0},
            "map": "corridor",
            "time": self.time,
        }


def make_fake_sim() -> FakeSim:
    """Module-level factory, picklable for start_server_process."""
    return FakeSim()


class FakeSimAt:
    """Picklable factory for a FakeSim starting at ``x`` with simulated time ``t``."""

    def __init__(self, x: float, t: float = 0.0) -> None:
        self.x, self.t = x, t

    def __call__(self) -> FakeSim:
        sim = FakeSim(self.x)
        sim.time = self.t
        return sim


def build_velocitynet_onnx(
    path: str,
    h: int = H,
    w: int = W,
    horizon: int = 2,
    gain: float = 20.0,
    meta_overrides: dict[str, str] | None = None,
    input_names: tuple[str, str] = ("current", "subgoal"),
    output_name: str = "velocities",
    output_scale: float = 1.0,
    drop_meta: tuple[str, ...] = (),
) -> str:
    """Write a tiny ONNX model with VelocityNet's signature and metadata; returns ``path``.

    ``output_scale=nan`` makes every output NaN (a broken model); the other knobs build mismatched models.
    """
    import onnx
    from onnx import TensorProto, helper

    from vtr.runtime.model_meta import ModelMeta

    cur, sub = input_names
    nodes = [
        helper.make_node("ReduceMean", [cur], ["mc"], axes=[1, 2, 3], keepdims=0),  # (1,)
        helper.make_node("ReduceMean", [sub], ["ms"], axes=[1, 2, 3], keepdims=0),  # (1,)
        helper.make_node("Sub", ["ms", "mc"], ["d"]),
        helper.make_node("Mul", ["d", "gain"], ["dg"]),
        helper.make_node("Tanh", ["dg"], ["t"]),
        helper.make_node("Mul", ["t", "half"], ["v"]),  # (1,)
        helper.make_node("Mul", ["v", "zero"], ["w"]),  # (1,)
        helper.make_node("Concat", ["v", "w"], ["vw"], axis=0),  # (2,)
        helper.make_node("Reshape", ["vw", "shape"], ["vw3"]),  # (1, 2, 1)
        helper.make_node("Tile", ["vw3", "reps"], ["tiled"]),  # (1, 2, N)
        helper.make_node("Mul", ["tiled", "scale"], [output_name]),
    ]
    inits = [
        helper.make_tensor("gain", TensorProto.FLOAT, [], [gain]),
        helper.make_tensor("half", TensorProto.FLOAT, [], [0.5]),
        helper.make_tensor("zero", TensorProto.FLOAT, [], [0.0]),
        helper.make_tensor("shape", TensorProto.INT64, [3], [1, 2, 1]),
        helper.make_tensor("reps", TensorProto.INT64, [3], [1, 1, horizon]),
        helper.make_tensor("scale", TensorProto.FLOAT, [], [output_scale]),
    ]
    graph = helper.make_graph(
        nodes,
        "tiny_velocitynet",
        [
            helper.make_tensor_value_info(cur, TensorProto.FLOAT, [1, 3, h, w]),
            helper.make_tensor_value_info(sub, TensorProto.FLOAT, [1, 3, h, w]),
        ],
        [helper.make_tensor_value_info(output_name, TensorProto.FLOAT, [1, 2, horizon])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    props = ModelMeta(image_height=h, image_width=w, horizon=horizon).to_props()
    props.update(meta_overrides or {})
    for key in drop_meta:
        props.pop(key)
    helper.set_model_props(model, props)
    onnx.checker.check_model(model)
    onnx.save(model, path)
    return path


def corridor_route(length_m: float = 0.4, spacing_m: float = 0.05, h: int = H, w: int = W):
    """A Route along the corridor: subgoals every ``spacing_m`` from x=0 to ``length_m``."""
    from vtr.runtime.route import Route

    xs = np.arange(0.0, length_m + 1e-9, spacing_m)
    images = np.stack([render(x, h, w) for x in xs])
    poses = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], axis=1)
    commands = np.zeros((len(xs), 2))
    commands[:-1, 0] = 0.25
    return Route(images=images, poses=poses, commands=commands, name="corridor", dt=0.1)


def run_repeat(robot, policy, route, cfg=None, log=None, stop_event=None):
    """Run a whole repeat with ``runtime.repeater.Repeater``; ``log`` receives each command's log dict."""
    from vtr.runtime.repeater import Repeater

    def on_step(record) -> None:
        if log is not None and record.commanded:
            log(record.to_log())

    return Repeater(robot, policy, route, config=cfg, on_step=on_step, stop_event=stop_event).run()
