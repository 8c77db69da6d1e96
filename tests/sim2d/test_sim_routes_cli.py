"""Shipped routes drive collision-free; the snapshot CLI, the serve fallback, the gym adapter and the benchmark run."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from vtr.sim2d import SimConfig, Simulator, list_routes, load_route


@pytest.fixture(scope="module")
def sim() -> Simulator:
    return Simulator(SimConfig())


def test_paper_scenarios_and_enough_routes_are_shipped():
    names = list_routes()
    assert {"translation", "rotation", "translation_rotation"} <= set(names)
    assert len(names) >= 13
    rot = load_route("rotation")
    assert all(s.v == 0 for s in rot.segments)
    assert rot.segments[0].w < 0 < rot.segments[-1].w  # clockwise, then back counter-clockwise
    assert sum(s.w * s.duration for s in rot.segments) == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("name", list_routes())
def test_route_is_collision_free_in_the_noiseless_simulator(sim, name):
    route = load_route(name)
    sim.reset(route.start)
    r = sim.cfg.robot_radius
    for v, w, d in route.commands(0.1):
        sim.advance(v, w, d)
        p = sim.pose
        assert not sim.collided, f"{name} touched an obstacle at {p}"
        assert sim.house.is_free(p.x, p.y, r), f"{name} left free space at {p}"
    assert sim.time == pytest.approx(route.duration)


def test_route_validation(tmp_path):
    bad = tmp_path / "r.json"
    bad.write_text(
        json.dumps(
            {"name": "r", "start": {"x": 1, "y": 2, "yaw": 0}, "segments": [{"v": 2, "w": 0, "duration": 1}]}
        )
    )
    with pytest.raises(ValueError, match="exceeds the limits"):
        load_route(bad)
    bad.write_text(
        json.dumps({"name": "r", "start": {"x": 1, "y": 2}, "segments": [{"v": 0, "w": 0, "duration": 1}]})
    )
    with pytest.raises(ValueError, match="start.yaw"):
        load_route(bad)
    with pytest.raises(ValueError, match="route not found"):
        load_route("nowhere")


def _cli(argv: list[str]) -> int:
    from vtr.cli import main

    return main(["sim", *argv])


def test_snapshot_cli_writes_a_png(tmp_path, capsys):
    import cv2

    out = tmp_path / "sub" / "house.png"
    assert _cli(["snapshot", "--out", str(out), "--x", "8.0", "--y", "2.0", "--yaw", "1.0"]) == 0
    img = cv2.imread(str(out))
    assert img is not None and img.shape[1] > img.shape[0] > 300
    assert "kitchen" in capsys.readouterr().out
    assert list(out.parent.iterdir()) == [out]  # no temporary file left behind
    assert _cli(["snapshot", "--out", str(out), "--x", "6.0", "--y", "1.0"]) == 2  # inside a wall
    assert "not free" in capsys.readouterr().err


def test_serve_without_server_module_says_so(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "vtr.sim2d.server", None)  # as if the module did not exist
    assert _cli(["serve", "--bind", "tcp://127.0.0.1:5599"]) == 3
    assert "sim2d/server.py" in capsys.readouterr().err


def test_gym_env_passes_check_env():
    from gymnasium.utils.env_checker import check_env

    from vtr.sim2d import CameraConfig
    from vtr.sim2d.gym_env import GymEnvConfig, SimEnv

    env = SimEnv(GymEnvConfig(sim=SimConfig(camera=CameraConfig(width=48, height=32)), max_steps=5))
    check_env(env, skip_render_check=True)
    obs, info = env.reset(seed=4)
    assert obs.shape == (32, 48, 3) and obs.dtype == np.uint8
    obs2, reward, terminated, truncated, info2 = env.step(np.array([1.0, 0.0], dtype=np.float32))
    assert reward > 0.04 and not terminated and not truncated  # 0.5 m/s for 0.1 s straight ahead
    assert not np.array_equal(obs, obs2)


def test_throughput_benchmark_smoke(tmp_path):
    from vtr.benchmarks.sim_throughput import SimBenchConfig, format_table, run

    out = tmp_path / "bench.json"
    r = run(SimBenchConfig(steps=20, warmup=2, width=32, height=32, json_path=str(out)))
    assert r["steps_per_s"] > 0 and r["render_ms_median"] > 0 and r["physics_ms_median"] > 0
    assert json.loads(out.read_text())["config"]["steps"] == 20
    assert "steps/s" in format_table(r)
