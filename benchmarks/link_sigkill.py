"""`vtr bench link sigkill`: SIGKILL `vtr repeat --motion continuous` mid-route on a realtime simulator and time how
long the robot keeps moving (the simulator's cmd_vel_timeout watchdog must bring it to rest).

An observer polls ``observe`` every ~10 ms on its own connection (``observe`` is not a motion command, so it
does not feed the watchdog) and records the pose. The rest delay of a trial is the time from the kill to
the first observation showing the final pose: an upper bound, within one poll, of when the robot stopped.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import zmq

import vtr
from vtr.runtime import protocol

REPO = Path(vtr.__file__).resolve().parents[1]


def _observer(endpoint: str) -> tuple[zmq.Context, zmq.Socket]:
    ctx = zmq.Context()
    sock = ctx.socket(zmq.REQ)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.RCVTIMEO, 2000)
    sock.connect(endpoint)
    return ctx, sock


def _pose(sock: zmq.Socket, seq: int) -> tuple[float, float, float] | None:
    sock.send_multipart(protocol.encode_request("observe", seq))
    return protocol.decode_reply(sock.recv_multipart()).pose


def _teach(model_dir: Path, route: str) -> Path:
    from vtr.runtime.teach import TeachConfig, TeachRunConfig, run
    from vtr.sim2d.routes import ROUTES_DIR
    from vtr.sim2d.server import ServerConfig, start_server_process

    out = model_dir / f"{route}.npz"
    server = start_server_process(ServerConfig(bind="tcp://127.0.0.1:*"))
    try:
        run(
            TeachRunConfig(
                sim=server.endpoint,
                route=str(ROUTES_DIR / f"{route}.json"),
                out=str(out),
                teach=TeachConfig(),
            )
        )
    finally:
        server.terminate()
    return out


def sigkill(
    trials: int = 20,
    seed: int = 0,
    model: str | None = None,
    route: str = "living_s_curve",
    cmd_vel_timeout: float = 0.5,
) -> dict[str, Any]:
    """``cmd_vel_timeout`` 0 is the control: without the watchdog the robot should keep moving."""
    from vtr.sim2d.server import ServerConfig, start_server_process

    rng = random.Random(seed)
    model = model or str(REPO / "models" / "velocitynet.onnx")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    delays, moving_at_kill, at_rest = [], 0, 0
    with tempfile.TemporaryDirectory() as tmp:
        route_path = _teach(Path(tmp), route)
        for _ in range(trials):
            cfg = ServerConfig(
                bind="tcp://127.0.0.1:*", mode="realtime", cmd_vel_timeout=cmd_vel_timeout, poll_ms=20
            )
            server = start_server_process(cfg)
            cmd = [
                sys.executable,
                "-m",
                "vtr.runtime.cli",
                "repeat",
                "--sim",
                server.endpoint,
                "--model",
                model,
            ]
            cmd += ["--route", str(route_path), "--motion", "continuous"]
            runtime = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            ctx, sock = _observer(server.endpoint)
            seq, trace = 0, []  # (monotonic time, pose)
            try:
                moving_since = None
                wait = rng.uniform(0.3, 1.5)
                while moving_since is None or time.monotonic() - moving_since < wait:
                    seq += 1
                    trace.append((time.monotonic(), _pose(sock, seq)))
                    if moving_since is None and len(trace) > 1 and trace[-1][1] != trace[-2][1]:
                        moving_since = time.monotonic()
                    if time.monotonic() - trace[0][0] > 60:
                        raise RuntimeError("the repeat never moved the robot")
                    time.sleep(0.01)
                runtime.send_signal(signal.SIGKILL)
                t_kill = time.monotonic()
                moving_at_kill += int(trace[-1][1] != trace[-2][1])
                while time.monotonic() - t_kill < 1.5:
                    seq += 1
                    trace.append((time.monotonic(), _pose(sock, seq)))
                    time.sleep(0.01)
            finally:
                runtime.kill()
                runtime.wait()
                sock.close()
                ctx.term()
                server.terminate()
            final = trace[-1][1]
            changed = [i for i, (_, p) in enumerate(trace) if p != final]
            settled = trace[changed[-1] + 1][0] if changed else t_kill  # first observation of the final pose
            delays.append(max(0.0, settled - t_kill))
            # the robot is at rest: the last 0.5 s of observations all show the final pose
            at_rest += int(all(p == final for t, p in trace if t > trace[-1][0] - 0.5))
    delays.sort()
    return {
        "trials": trials,
        "moving_at_kill": moving_at_kill,
        "at_rest_at_end": at_rest,
        "rest_delay_s_p50": round(delays[len(delays) // 2], 3),
        "rest_delay_s_p100": round(delays[-1], 3),
        "within_0_6_s": sum(d <= 0.6 for d in delays),
        "rest_delay_s_all": [round(d, 3) for d in delays],
        "cmd_vel_timeout_s": cmd_vel_timeout,
    }
