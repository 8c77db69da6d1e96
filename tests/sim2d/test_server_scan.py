"""`vtr sim serve` announces its range scanner and sends a scan with every image; `--no-scan` serves a
camera-only robot; the client puts the scan on its observations."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from vtr.runtime.client import SimClient
from vtr.sim2d import CameraConfig, SimConfig, Simulator
from vtr.sim2d.cli import add_serve_arguments
from vtr.sim2d.local_robot import LocalRobot
from vtr.sim2d.server import ServerConfig, ServerThread, SimServer

START = (2.8, 3.0, 0.0)


def small_sim() -> Simulator:
    return Simulator(SimConfig(camera=CameraConfig(width=32, height=32)))


def test_the_client_receives_the_scan_the_simulator_takes():
    local = LocalRobot(small_sim(), scan=True)
    expected = [local.reset(pose=START), local.step(0.3, 0.2, 0.1), local.step(0.0, -0.5, 0.1)]
    with ServerThread(small_sim()) as server, SimClient(server.endpoint, timeout_s=10.0) as client:
        before = client.reset(pose=START)  # no handshake yet: the client knows of no scanner
        assert before.scan is None
        hello = client.handshake()
        assert hello.scan == local.sim.rangefinder.spec
        got = [client.reset(pose=START), client.step(0.3, 0.2, 0.1), client.step(0.0, -0.5, 0.1)]
    for a, b in zip(expected, got, strict=True):
        assert b.scan is not None and b.scan.x_m == a.scan.x_m and b.scan.matches(hello.scan)
        # the wire carries millimetres
        np.testing.assert_allclose(b.scan.ranges, a.scan.ranges, atol=6e-4)
        np.testing.assert_array_equal(np.isinf(b.scan.ranges), np.isinf(a.scan.ranges))


def test_no_scan_serves_a_camera_only_robot():
    with (
        ServerThread(small_sim(), ServerConfig(bind="tcp://127.0.0.1:*", scan=False)) as server,
        SimClient(server.endpoint, timeout_s=10.0) as client,
    ):
        assert client.handshake().scan is None
        assert "scan" not in client.hello()
        assert client.reset(pose=START).scan is None


def test_a_realtime_server_sends_the_scan_too():
    cfg = ServerConfig(bind="tcp://127.0.0.1:*", mode="realtime", realtime_factor=4.0)
    with ServerThread(small_sim(), cfg) as server, SimClient(server.endpoint, timeout_s=10.0) as client:
        client.handshake()
        assert client.step(0.2, 0.0, 0.1).scan is not None


def test_a_simulator_without_a_scanner_announces_none():
    class NoScanner:  # the Simulator API without `rangefinder`
        def __init__(self) -> None:
            self.inner = small_sim()

        def __getattr__(self, name: str):
            if name in ("rangefinder", "scan"):
                raise AttributeError(name)
            return getattr(self.inner, name)

    server = SimServer(NoScanner())
    assert server.scan_spec is None and "scan" not in server.announce()


@pytest.mark.parametrize(("argv", "scan"), [([], True), (["--no-scan"], False)])
def test_the_cli_flag(argv, scan):
    parser = argparse.ArgumentParser()
    add_serve_arguments(parser)
    assert parser.parse_args(argv).scan is scan
