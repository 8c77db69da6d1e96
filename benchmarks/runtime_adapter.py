"""The runtime pieces the benchmarks time, behind one small interface.

The latency benchmark wants the runtime's own code on the hot path: the wire protocol's encode/decode,
`runtime.policy.OnnxPolicy` and `runtime.controller`. It imports no torch, OpenCV or pymunk: the
runtime-only memory probe loads it with those blocked.
"""

from __future__ import annotations

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


def frame_codec() -> FrameCodec:
    """The runtime's wire codec (runtime.protocol)."""
    from vtr.runtime import protocol

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

    return FrameCodec("vtr.runtime.protocol (encode_image_reply / decode_reply / encode_request)", enc_obs, dec_obs,
                      enc_cmd)  # fmt: skip


class ControlStep:
    """One control step: encoded frame in -> image error -> inference -> encoded command out.

    With the runtime installed this is its own code: ``runtime.controller.Controller.decide`` (image error
    against the subgoal) and ``runtime.policy.OnnxPolicy.predict`` (preprocess, inference, postprocess).
    The controller is set up so that every step commands (fixed e_m below any error, no stall guard): the
    worst case, a step that does not switch subgoal.
    """

    def __init__(self, model: str | Path, threads: int, subgoal: np.ndarray, codec: FrameCodec) -> None:
        from vtr.runtime.controller import Controller, ControllerConfig
        from vtr.runtime.policy import OnnxPolicy

        self.policy = OnnxPolicy(model, threads=threads)
        self._subgoals = np.ascontiguousarray(subgoal[None])
        self._cfg = ControllerConfig(e_m_mode="fixed", e_m=1e-3, stall_steps=0)
        self.controller = Controller(self._subgoals, self._cfg)
        self._codec = codec
        self.name = "runtime: protocol decode + Controller.decide + OnnxPolicy.predict + encode_request"

    def infer(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL

        return self.policy.infer({INPUT_CURRENT: x, INPUT_SUBGOAL: y})

    def __call__(self, frames: list[bytes]) -> list[bytes]:
        image = self._codec.decode_observation(frames)
        decision = self.controller.decide(image)
        if decision.action.value != "command":  # the identical frame matched: start over
            self.controller = type(self.controller)(self._subgoals, self._cfg)
        vel = self.policy.predict(image, self.controller.subgoal)  # (2, N)
        return self._codec.encode_command(float(vel[0, 0]), float(vel[1, 0]))


def control_step(model: str | Path, threads: int, subgoal: np.ndarray, codec: FrameCodec) -> ControlStep:
    return ControlStep(model, threads, subgoal, codec)


def zmq_round_trip(steps: int, warmup: int, image_size: tuple[int, int] = (128, 128)) -> dict[str, Any]:
    """Round trips of observe and step requests to a simulator server process on loopback.

    Each is the client's full exchange (encode, send, server work, receive, validate); the server's share
    (rendering the camera) is measured in-process alongside, so the transport's cost is the difference.
    """
    from vtr.benchmarks.latency import time_interleaved
    from vtr.runtime.client import SimClient
    from vtr.sim2d import CameraConfig, SimConfig, Simulator
    from vtr.sim2d.server import ServerConfig, start_server_process

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
