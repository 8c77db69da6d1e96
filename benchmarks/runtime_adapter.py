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
    """The runtime's wire codec (runtime.protocol) when installed, else the fallback."""
    try:
        from runtime import protocol
    except ImportError:
        return _fallback_codec()
    session = "bench"

    def enc_obs(image: np.ndarray) -> list[bytes]:
        return protocol.encode_image_reply("step", 1, session, 1.0, image, pose=None)

    def dec_obs(frames: list[bytes]) -> np.ndarray:
        # what SimClient does with a reply: validate header, cmd, seq and shape, then view the pixels
        reply = protocol.decode_reply(frames, expect_cmd="step", expect_seq=1)
        assert reply.image is not None
        return reply.image

    def enc_cmd(v: float, w: float) -> list[bytes]:
        return protocol.encode_request("step", 2, stamp=time.time(), v=v, w=w, duration=0.1)

    return FrameCodec("runtime.protocol (encode_image_reply / decode_reply / encode_request)", enc_obs, dec_obs,
                      enc_cmd)  # fmt: skip


class ControlStep:
    """One control step: encoded frame in -> image error -> inference -> encoded command out.

    With the runtime installed this is its own code: ``runtime.controller.Controller.decide`` (image error
    against the subgoal) and ``runtime.policy.OnnxPolicy.predict`` (preprocess, inference, postprocess).
    The controller is set up so that every step commands (fixed e_m below any error, no stall guard): the
    worst case, a step that does not switch subgoal.
    """

    def __init__(self, model: str | Path, threads: int, subgoal: np.ndarray, codec: FrameCodec) -> None:
        from runtime.controller import Controller, ControllerConfig
        from runtime.policy import OnnxPolicy

        self.policy = OnnxPolicy(model, threads=threads)
        self._subgoals = np.ascontiguousarray(subgoal[None])
        self._cfg = ControllerConfig(e_m_mode="fixed", e_m=1e-3, stall_steps=0)
        self.controller = Controller(self._subgoals, self._cfg)
        self._codec = codec
        self.name = "runtime: protocol decode + Controller.decide + OnnxPolicy.predict + encode_request"

    def infer(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        from runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL

        return self.policy.infer({INPUT_CURRENT: x, INPUT_SUBGOAL: y})

    def __call__(self, frames: list[bytes]) -> list[bytes]:
        image = self._codec.decode_observation(frames)
        decision = self.controller.decide(image)
        if decision.action.value != "command":  # the identical frame matched: start over
            self.controller = type(self.controller)(self._subgoals, self._cfg)
        vel = self.policy.predict(image, self.controller.subgoal)  # (2, N)
        return self._codec.encode_command(float(vel[0, 0]), float(vel[1, 0]))


class FallbackControlStep:
    """The same step from runtime.preprocess + onnxruntime, for when the runtime's modules are absent."""

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


def control_step(
    model: str | Path, threads: int, subgoal: np.ndarray, codec: FrameCodec
) -> ControlStep | FallbackControlStep:
    try:
        import runtime.controller  # noqa: F401
        import runtime.policy  # noqa: F401
    except ImportError:
        return FallbackControlStep(model, threads, subgoal, codec)
    return ControlStep(model, threads, subgoal, codec)


def zmq_round_trip(steps: int, warmup: int, image_size: tuple[int, int] = (128, 128)) -> dict[str, Any]:
    """Round trips of observe and step requests to a simulator server process on loopback.

    Each is the client's full exchange (encode, send, server work, receive, validate); the server's share
    (rendering the camera) is measured in-process alongside, so the transport's cost is the difference.
    """
    from benchmarks.latency import time_interleaved
    from runtime.client import SimClient
    from sim2d import CameraConfig, SimConfig, Simulator
    from sim2d.server import ServerConfig, start_server_process

    h, w = image_size
    sim_cfg = SimConfig(camera=CameraConfig(width=w, height=h), noise=0.0)
    server = start_server_process(ServerConfig(bind="tcp://127.0.0.1:*", sim=sim_cfg))
    try:
        client = SimClient(server.endpoint, timeout_s=5.0, expect_shape=(h, w))
        try:
            client.reset(seed=0)
            local = Simulator(sim_cfg)
            local.reset(seed=0)
            calls = time_interleaved(
                {
                    "observe": client.observe,
                    "step": lambda: client.step(0.0, 0.0, 0.1),
                    "render_in_process": local.observe,
                },
                steps,
                warmup,
            )
        finally:
            client.close()
    finally:
        server.terminate()
    transport = calls["observe"]["p50_ms"] - calls["render_in_process"]["p50_ms"]
    return {"endpoint": server.endpoint, "calls": calls, "transport_p50_ms": transport}
