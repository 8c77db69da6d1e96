"""The example bridge (examples/minimal_robot_server.py), run as a user would, passes `vtr check-robot` and can be
taught a route."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from vtr.runtime.check_robot import PASS, run_checks
from vtr.runtime.client import SimClient
from vtr.runtime.route_script import parse_route_script
from vtr.runtime.teach import TeachConfig, teach

SCRIPT = Path(__file__).resolve().parents[2] / "examples" / "minimal_robot_server.py"


@contextmanager
def _serve(*options: str) -> Iterator[str]:
    proc = subprocess.Popen(
        [sys.executable, str(SCRIPT), "--bind", "tcp://127.0.0.1:*", *options],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline() if proc.stdout else ""
        assert line.startswith("minimal robot server on tcp://"), line
        yield line.split()[-1]
    finally:
        proc.terminate()
        proc.wait(5)


@pytest.fixture(scope="module")
def endpoint() -> Iterator[str]:
    with _serve() as address:
        yield address


def test_the_example_passes_every_check(endpoint: str) -> None:
    results = run_checks(endpoint, timeout_s=2.0)
    assert all(r.status == PASS for r in results), [(r.name, r.status, r.detail) for r in results]


def test_the_example_with_actuation_noise_passes_every_check() -> None:
    with _serve("--noise", "0.05") as address:
        results = run_checks(address, timeout_s=2.0)
    assert all(r.status == PASS for r in results), [(r.name, r.status, r.detail) for r in results]


def test_the_example_can_be_taught_a_route(endpoint: str) -> None:
    script = parse_route_script(
        {
            "start": {"x": -1.0, "y": 0.0, "yaw": 0.0},
            "segments": [{"v": 0.3, "w": 0.0, "duration": 2.0}, {"v": 0.0, "w": 0.5, "duration": 1.0}],
        }
    )
    with SimClient(endpoint, timeout_s=2.0) as client:
        route = teach(client, script, TeachConfig())
    assert len(route) == 16  # 30 control steps, a subgoal every 2, plus the start
    assert route.camera["fov_deg"] == 90.0 and route.camera["height_m"] == 0.3  # from hello, for the checks
    assert route.poses[-1][0] == pytest.approx(-0.4, abs=1e-6)
    assert route.poses[-1][2] == pytest.approx(0.5, abs=1e-6)


def test_collect_repeat_and_eval_work_on_the_example_unchanged(
    endpoint: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from vtr import cli
    from vtr.training.dataset import load_dataset

    data = tmp_path / "room"  # `collect --sim` records a folder of shards
    assert (
        cli.main(["collect", "--sim", endpoint, "--out", str(data), "--frames", "200", "--no-progress"]) == 0
    )
    assert len(load_dataset(data, image_size=128)) == 200
    script = tmp_path / "arc.json"
    script.write_text(
        '{"start": {"x": -1.2, "y": -0.8, "yaw": 0.3}, "segments": [{"v": 0.2, "w": 0.0, "duration": 2.0},'
        ' {"v": 0.15, "w": 0.4, "duration": 2.0}]}'
    )
    route = tmp_path / "route.npz"
    assert cli.main(["teach", "--sim", endpoint, "--route", str(script), "--out", str(route)]) == 0
    model = Path(__file__).resolve().parents[2] / "models" / "velocitynet.onnx"
    run = tmp_path / "run.mcap"
    argv = ["repeat", "--sim", endpoint, "--model", str(model), "--route", str(route), "--mcap", str(run)]
    assert cli.main(argv) == 0  # the shipped model finishes the route in a room it never saw
    capsys.readouterr()
    assert cli.main(["eval", "--run", str(run), "--taught", str(route)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["status"] == "finished" and result["position_error_m"]["mean"] < 0.05


def _drive(noise: float, seed: int) -> tuple[float, float, float]:
    """Where the example's robot ends after 2 s straight ahead, from a reset with ``seed``."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("minimal_robot_server", SCRIPT)
    assert spec and spec.loader
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    world = example.World(noise)
    world.reset(-1.0, 0.0, 0.0, seed=seed)
    for _ in range(20):
        world.step(0.3, 0.0, 0.1)
    world.step(0.0, 0.0, 0.1)  # a zero command stays a zero command under noise
    return world.x, world.y, world.yaw


def test_the_example_noise_perturbs_motion_reproducibly() -> None:
    assert _drive(0.0, 3) == pytest.approx((-0.4, 0.0, 0.0), abs=1e-9)  # no noise: the exact unicycle
    noisy = _drive(0.05, 3)
    assert noisy == _drive(0.05, 3)  # same seed, same motor errors
    assert noisy != _drive(0.05, 4)
    assert 1e-4 < abs(noisy[0] + 0.4) < 0.1 and abs(noisy[2]) > 1e-5  # off the ideal end, but not wildly


def test_the_room_routes_parse_and_stay_clear_of_the_walls() -> None:
    import importlib.util

    spec = importlib.util.spec_from_file_location("minimal_robot_server", SCRIPT)
    assert spec and spec.loader
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    routes = sorted((SCRIPT.parent / "room_routes").glob("*.json"))
    assert len(routes) == 8
    for path in routes:
        script = parse_route_script(json.loads(path.read_text()))
        world = example.World()
        world.reset(*script.start)
        for seg in script.segments:
            for _ in range(round(seg.duration / 0.1)):
                world.step(seg.v, seg.w, 0.1)
                assert not world.collided and max(abs(world.x), abs(world.y)) < example.HALF - 0.25, path.name
