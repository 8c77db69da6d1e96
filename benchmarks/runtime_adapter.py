"""The runtime pieces the benchmarks time, behind one small interface.

The latency benchmark wants the runtime's own code on the hot path: the wire protocol's encode/decode,
`runtime.policy.OnnxPolicy` and `runtime.controller`. This module binds to them and, where one is not
installed yet, falls back to a minimal equivalent built from `runtime.preprocess` and onnxruntime, naming
which one it used so a report never passes a stand-in off as the real thing. It imports no torch, OpenCV
or pymunk: the runtime-only memory probe loads it with those blocked.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np


@dataclass
class FrameCodec:
    """Encode/decode of the frames the daemon receives (an observation) and sends (a command)."""

    name: str
    encode_observation: Callable[[np.ndarray], list[bytes]]
    decode_observation: Callable[[list[bytes]], np.ndarray]
    encode_command: Callable[[float, float], list[bytes]]


def _fallback_codec() -> FrameCodec:
    """JSON header frame + raw rgb8 pixel frame, the shape DESIGN.md prescribes for the wire."""

    def enc_obs(image: np.ndarray) -> list[bytes]:
        h, w = image.shape[:2]
        header = {"protocol": "vtr", "version": 1, "cmd": "observation", "seq": 0, "stamp": 0.0}
        header.update(encoding="rgb8", height=h, width=w)
        return [json.dumps(header).encode(), np.ascontiguousarray(image).tobytes()]

    def dec_obs(frames: list[bytes]) -> np.ndarray:
        header = json.loads(frames[0])
        if header.get("encoding") != "rgb8":
            raise ValueError(f"unsupported encoding {header.get('encoding')!r}")
        return np.frombuffer(frames[1], dtype=np.uint8).reshape(header["height"], header["width"], 3)

    def enc_cmd(v: float, w: float) -> list[bytes]:
        header = {"protocol": "vtr", "version": 1, "cmd": "step", "seq": 0, "stamp": time.time()}
        header.update(v=v, w=w, duration=0.1)
        return [json.dumps(header).encode()]

    return FrameCodec("fallback json+rgb8 (runtime.protocol not available)", enc_obs, dec_obs, enc_cmd)


def frame_codec() -> FrameCodec:
    """The runtime's wire codec when installed, else the fallback."""
    try:
        from runtime import protocol  # noqa: F401
    except ImportError:
        return _fallback_codec()
    return _runtime_codec()


def _runtime_codec() -> FrameCodec:
    # Bound once runtime.protocol has landed; until then the fallback is used.
    return _fallback_codec()


class ControlStep:
    """One control step: encoded frame in -> image error -> (maybe) inference -> encoded command out.

    Always runs inference (the worst case, a step that does not switch subgoal).
    """

    def __init__(self, model: str | Path, threads: int, subgoal: np.ndarray, codec: FrameCodec) -> None:
        import onnxruntime as ort

        from runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL
        from runtime.preprocess import image_error, to_nchw

        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads
        opts.inter_op_num_threads = 1
        self._sess = ort.InferenceSession(str(model), opts, providers=["CPUExecutionProvider"])
        self._names = (INPUT_CURRENT, INPUT_SUBGOAL)
        self._subgoal = subgoal
        self._subgoal_nchw = to_nchw(subgoal)
        self._to_nchw, self._image_error = to_nchw, image_error
        self._codec = codec
        self.name = "fallback: runtime.preprocess + onnxruntime (runtime.controller not available)"

    def infer(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self._sess.run(None, {self._names[0]: x, self._names[1]: y})[0]

    def __call__(self, frames: list[bytes]) -> list[bytes]:
        image = self._codec.decode_observation(frames)
        self._image_error(image, self._subgoal)
        vel = self.infer(self._to_nchw(image), self._subgoal_nchw)  # (1, 2, N)
        return self._codec.encode_command(float(vel[0, 0, 0]), float(vel[0, 1, 0]))


def control_step(model: str | Path, threads: int, subgoal: np.ndarray, codec: FrameCodec) -> ControlStep:
    return ControlStep(model, threads, subgoal, codec)


def zmq_round_trip(steps: int, warmup: int) -> dict[str, Any]:
    """Round trip of observe / step requests to a simulator server on loopback."""
    raise ImportError("sim2d.server / runtime.client not available yet")
