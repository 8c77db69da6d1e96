"""The ZeroMQ round trip to a simulator server process on loopback (`vtr bench latency`'s transport
figure)."""

from __future__ import annotations

from typing import Any

from vtr.benchmarks.timing import time_interleaved
from vtr.runtime.contracts import CONTROL_DT


def zmq_round_trip(steps: int, warmup: int, image_size: tuple[int, int] = (128, 128)) -> dict[str, Any]:
    """Round trips of observe and step requests to a simulator server process on loopback.

    Each is the client's full exchange (encode, send, server work, receive, validate); the server's share
    (rendering the camera) is measured in-process alongside, so the transport's cost is the difference.
    """
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
                    "step": lambda: client.step(0.0, 0.0, CONTROL_DT),
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
