"""The server and LocalRobot around the real sim2d.Simulator: the wire adds nothing and loses nothing."""

from __future__ import annotations

import numpy as np
import pytest

try:
    from vtr.sim2d import CameraConfig, SimConfig, Simulator
except ImportError:  # the simulator core has not landed on this branch yet
    Simulator = None

pytestmark = pytest.mark.skipif(Simulator is None, reason="sim2d.Simulator is not available")


def small_sim() -> Simulator:
    return Simulator(SimConfig(camera=CameraConfig(width=32, height=32), noise=0.0))


def test_images_over_zeromq_equal_the_in_process_ones():
    from vtr.runtime.client import SimClient
    from vtr.sim2d.local_robot import LocalRobot
    from vtr.sim2d.server import ServerThread

    commands = [(0.3, 0.0), (0.2, 0.5), (0.0, -1.0), (0.5, 0.2)]
    local = LocalRobot(small_sim())
    start = local.reset(seed=2)
    with ServerThread(small_sim()) as server, SimClient(server.endpoint, timeout_s=10.0) as client:
        hello = client.hello()
        assert hello["camera"]["width"] == 32 and hello["limits"]["v_max"] == 0.5
        remote = client.reset(seed=2)
        np.testing.assert_array_equal(remote.image, start.image)
        assert remote.pose == pytest.approx(start.pose)
        for v, w in commands:
            a, b = local.step(v, w, 0.1), client.step(v, w, 0.1)
            np.testing.assert_array_equal(a.image, b.image)
            assert a.pose == pytest.approx(b.pose) and a.stamp == pytest.approx(b.stamp)
        client.stop()
        local.stop()
        assert client.observe().stamp == pytest.approx(0.1 * len(commands))  # lockstep: stop adds no time
    assert local.commands[-1] == (0.0, 0.0, 0.0)


def test_simulator_refusal_is_an_error_reply_and_the_server_keeps_serving():
    from vtr.runtime.client import SimClient
    from vtr.runtime.robot import RobotError
    from vtr.sim2d.server import ServerThread

    with ServerThread(small_sim()) as server, SimClient(server.endpoint, timeout_s=10.0) as client:
        with pytest.raises(RobotError, match="not free space"):
            client.reset(pose=(-100.0, -100.0, 0.0))
        assert client.observe().image.shape == (32, 32, 3)


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_vtr_sim_serve_shuts_down_cleanly_on_signals(sig):
    import os
    import signal
    import subprocess
    import sys
    from pathlib import Path

    from vtr.runtime.client import SimClient
    from vtr.sim2d.server import ServerThread

    with ServerThread(small_sim()) as probe:  # borrow a free port
        endpoint = probe.endpoint
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen(
        [sys.executable, "-m", "vtr.cli", "sim", "serve", "--bind", endpoint],
        cwd=root,
        env=dict(os.environ, PYTHONPATH=str(root)),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert "listening on" in proc.stdout.readline()
        with SimClient(endpoint, timeout_s=10.0) as client:
            assert client.observe().image.shape == (128, 128, 3)
        proc.send_signal(getattr(signal, sig))
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "stopped after 1 requests (0 refused)" in out
