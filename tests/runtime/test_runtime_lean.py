"""The runtime in a clean process with torch, pymunk, cv2, onnx and sim2d blocked: the robot board's view.

Each test runs `vtr` in a subprocess whose sys.modules marks those packages as absent, against a
simulator server running in this (test) process.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from runtime_fakes import FakeSim, build_velocitynet_onnx, corridor_route

from vtr.sim2d.server import ServerThread

ROOT = Path(__file__).resolve().parents[2]
BLOCKED = ("torch", "pymunk", "cv2", "onnx", "vtr.sim2d", "matplotlib", "gymnasium")

PRELUDE = f"""
import sys
for name in {BLOCKED!r}:
    sys.modules[name] = None
from vtr.runtime.cli import main
code = main(sys.argv[1:])
import vtr.runtime.client, vtr.runtime.controller, vtr.runtime.daemon, vtr.runtime.policy, vtr.runtime.protocol  # noqa
import vtr.runtime.robot, vtr.runtime.route, vtr.runtime.route_script, vtr.runtime.teach  # noqa
leaked = sorted(n for n in {BLOCKED!r} if sys.modules.get(n) is not None)
print("LEAKED", leaked, file=sys.stderr)
sys.exit(code)
"""


class FrozenSim(FakeSim):
    """The robot is stuck (wheels slipping, no bumper): time passes, the view never changes. It reports no
    contact, which would end the repeat at once (``stop_on_contact``)."""

    def step(self, v: float, w: float, duration: float):
        self.calls.append(("step", v, w, duration))
        self.time += duration
        time.sleep(0.005)  # a robot's pace: the run outlasts the test's signal
        return self.observe()


def _run_vtr(args: list[str], **kwargs) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen(
        [sys.executable, "-c", PRELUDE, *args],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kwargs,
    )


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("lean")
    model = build_velocitynet_onnx(str(folder / "tiny.onnx"))
    route = folder / "route.npz"
    corridor_route().save(route)
    corridor_route(length_m=10.0).save(folder / "long.npz")
    script = folder / "corridor.json"
    script.write_text(
        json.dumps({"start": {"x": 0, "y": 0, "yaw": 0}, "segments": [{"v": 0.25, "w": 0, "duration": 1.0}]})
    )
    return {
        "model": model,
        "route": str(route),
        "long_route": str(folder / "long.npz"),
        "script": str(script),
        "folder": folder,
    }


def test_teach_and_repeat_run_with_torch_pymunk_cv2_blocked(files):
    with ServerThread(FakeSim()) as server:
        taught = str(files["folder"] / "taught.npz")
        teach = _run_vtr(["teach", "--sim", server.endpoint, "--route", files["script"], "--out", taught])
        out, err = teach.communicate(timeout=60)
        assert teach.returncode == 0, err
        assert "LEAKED []" in err
        args = ["repeat", "--sim", server.endpoint, "--model", files["model"], "--route", taught, "--json"]
        args += ["--profile", "paper"]  # the fake policy steers on brightness, which light matching evens out
        proc = _run_vtr(args)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "LEAKED []" in err
    summary = json.loads(out)
    assert summary["completed"] and summary["subgoals_reached"] == summary["subgoals_total"] == 6


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_commands_zero_velocity_and_exits_with_a_summary(files, sig):
    sim = FrozenSim()
    log = files["folder"] / f"run-{sig.name}.jsonl"
    with ServerThread(sim) as server:
        args = ["repeat", "--sim", server.endpoint, "--model", files["model"], "--route", files["route"]]
        # Algorithm 1 neither stalls nor gets lost: the robot is commanded until the signal, or the step
        # limit of this long route (8 per subgoal, at 5 ms a step); raw error, no light matching: the fake
        # camera encodes position in brightness
        args += ["--log", str(log), "--json", "--motion", "continuous", "--profile", "paper"]
        proc = _run_vtr(args)
        try:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline and (not log.exists() or len(log.read_text().splitlines()) < 3):
                time.sleep(0.05)
            assert proc.poll() is None, proc.communicate()[1]
            proc.send_signal(sig)
            out, err = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert server.server.last_cmd == "stop" and server.server.twist == (0.0, 0.0)
    assert proc.returncode == 130, err  # an interrupt, whatever stopped the robot
    summary = json.loads(out)
    assert summary["status"] == "interrupted" and summary["steps"] >= 3
    steps = [call for call in sim.calls if call[0] == "step"]
    assert steps and all(call[1] > 0.1 for call in steps)  # it was driving (no zero between steps)
