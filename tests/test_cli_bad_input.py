"""Bad input, as a new user types it: one line on stderr naming the problem, no traceback, the right exit
code (2 usage/input, 1 failed run, 130 interrupt), no hang (every subprocess runs under a timeout) and no
empty output left behind."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vtr.cli import main

ROOT = Path(__file__).resolve().parents[1]
MODEL = str(ROOT / "models" / "velocitynet.onnx")
VIEWNET = str(ROOT / "models" / "viewnet.pt")
ROUTE_JSON = str(ROOT / "sim2d" / "routes" / "translation.json")
NO_SERVER = "tcp://127.0.0.1:9"  # discard port: nothing answers


def _garbage(tmp_path: Path, name: str) -> str:
    path = tmp_path / name
    path.write_bytes(bytes(range(256)) * 3)
    return str(path)


def _inputs(tmp_path: Path) -> dict[str, str]:
    """The files the cases name: garbage of each kind, and real files given where another kind is wanted."""
    from vtr.runtime.route import Route

    subs = {
        f"{{garbage.{ext}}}": _garbage(tmp_path, f"garbage.{ext}") for ext in ("onnx", "npz", "pt", "json")
    }
    (tmp_path / "run.jsonl").write_text('{"step": 0, "v": 0.1, "w": 0.0}\n{"summary": {"steps": 1}}\n')
    (tmp_path / "run.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(64))
    zeros = np.zeros
    Route(zeros((2, 8, 8, 3), np.uint8), zeros((2, 3)), zeros((2, 2)), name="r", dt=0.1).save(
        tmp_path / "r.npz"
    )
    for name in ("run.jsonl", "run.png", "r.npz"):
        subs[f"{{{name}}}"] = str(tmp_path / name)
    return subs


def _one_line(err: str) -> str:
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    return lines[0]


def _in_process(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, str]:
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own exit (a usage error)
        code = int(exc.code or 0)
    return code, _one_line(capsys.readouterr().err)


def _repeat(*more: str, sim: str = NO_SERVER, model: str = MODEL, route: str = "r.npz") -> list[str]:
    return ["repeat", "--sim", sim, "--model", model, "--route", route, *more]


def _train(stage: str, *more: str) -> list[str]:
    return ["train", stage, "--preset", "tiny", *more, "--out", "{tmp}/run"]


CASES = {
    # name: (argv with {tmp} and {garbage.*} placeholders, words the message must hold)
    "repeat: http address": (_repeat(sim="http://127.0.0.1:5601"), "http://"),
    "repeat: no port": (_repeat(sim="tcp://127.0.0.1"), "no port"),
    "repeat: no transport": (_repeat(sim="127.0.0.1:5555"), "tcp://"),
    "repeat: speed 0": (_repeat("--speed", "0"), "--speed"),
    "repeat: wait -1": (_repeat("--wait", "-1"), "--wait"),
    "repeat: timeout 0": (_repeat("--timeout", "0"), "--timeout"),
    "repeat: stop beyond slowdown": (_repeat("--stop-distance", "0.9"), "--stop-distance"),
    "repeat: bad config file": (_repeat("--config", "{garbage.json}"), "garbage.json"),
    "repeat: a removed ablation flag": (_repeat("--stall-steps", "0"), "--stall-steps"),
    "repeat: garbage model": (_repeat(model="{garbage.onnx}"), "garbage.onnx"),
    "repeat: garbage route": (_repeat("--log", "{tmp}/run.jsonl", route="{garbage.npz}"), "garbage.npz"),
    "teach: timeout 0": (
        ["teach", "--sim", NO_SERVER, "--route", ROUTE_JSON, "--out", "{tmp}/t.npz", "--timeout", "0"],
        "--timeout",
    ),
    "teach: garbage route script": (
        ["teach", "--sim", NO_SERVER, "--route", "{garbage.json}", "--out", "{tmp}/t.npz"],
        "garbage.json",
    ),
    "collect: frames 0": (["collect", "--frames", "0", "--out", "{tmp}/d.npz"], "frames"),
    "collect: too few frames to train on": (
        ["collect", "--frames", "10", "--out", "{tmp}/d.npz"],
        "at least 123",
    ),
    "eval: unknown route": (["eval", "--routes", "nowhere", "--quick"], "nowhere"),
    "eval: garbage route file": (["eval", "--routes", "{garbage.json}", "--quick"], "garbage.json"),
    "eval: garbage model": (["eval", "--model", "{garbage.onnx}", "--quick"], "garbage.onnx"),
    "check-robot: garbage model": (["check-robot", NO_SERVER, "--model", "{garbage.onnx}"], "garbage.onnx"),
    "eval: noise 2": (["eval", "--noise", "2", "--quick"], "noise"),
    "bench latency: garbage model": (["bench", "latency", "--model", "{garbage.onnx}"], "garbage.onnx"),
    "bench latency: missing model": (["bench", "latency", "--model", "{tmp}/missing.onnx"], "missing.onnx"),
    "export: garbage checkpoint": (
        ["export", "--checkpoint", "{garbage.pt}", "--out", "{tmp}/o.onnx"],
        "garbage.pt",
    ),
    "train: garbage viewnet": (
        _train("velocitynet", "--data", "{tmp}/d.npz", "--viewnet", "{garbage.pt}"),
        "garbage.pt",
    ),
    "train: tiny preset with the shipped viewnet": (
        _train("velocitynet", "--data", "{tmp}/d.npz", "--viewnet", VIEWNET),
        "--preset",
    ),
    "train: garbage dataset": (_train("viewnet", "--data", "{garbage.npz}"), "garbage.npz"),
    "sim snapshot: jpeg": (["sim", "snapshot", "--out", "{tmp}/x.jpg"], ".png"),
    "demo: unknown route": (["demo", "--route", "nowhere", "--out", "{tmp}/demo"], "nowhere"),
    "demo: garbage model": (["demo", "--model", "{garbage.onnx}", "--out", "{tmp}/demo"], "garbage.onnx"),
    # careless inputs (issue 21): outputs checked before any is created, folders named as folders
    "repeat: a folder as --log": (_repeat("--log", "{tmp}"), "is a folder; name a file"),
    "repeat: --log under a file": (
        _repeat("--log", "{tmp}/garbage.json/run.jsonl"),
        "is a file, not a folder",
    ),
    "repeat: a file where the --mcap folder goes": (
        _repeat("--mcap", "{garbage.json}"),
        "a file is in the way",
    ),
    "repeat: --log and --mcap the same file": (
        _repeat("--log", "{tmp}/r.mcap", "--mcap", "{tmp}/r.mcap"),
        "same",
    ),
    "repeat: a folder as --model": (_repeat(model="{tmp}"), "is a folder, not a model file"),
    "repeat: a folder as --route": (_repeat(route="{tmp}"), "is a folder, not a route file"),
    "eval: a folder as --model": (["eval", "--model", "{tmp}", "--quick"], "is a folder, not a model file"),
    "eval: a folder as --viewnet": (["eval", "--viewnet", "{tmp}", "--quick"], "is a folder, not a model"),
    "eval: the repeat's own --log as --run": (
        ["eval", "--run", "{run.jsonl}", "--taught", "{r.npz}"],
        "--log",
    ),
    "eval: a PNG as --run": (["eval", "--run", "{run.png}", "--taught", "{r.npz}"], "PNG image"),
    "eval: a PNG as --taught": (["eval", "--run", "{run.png}", "--taught", "{run.png}"], "run.png"),
    "bench latency: a folder as --model": (["bench", "latency", "--model", "{tmp}"], "is a folder"),
    "export: a folder as --checkpoint": (
        ["export", "--checkpoint", "{tmp}", "--out", "{tmp}/o.onnx"],
        "folder",
    ),
    "export: no --out": (["export", "--checkpoint", "{garbage.pt}"], "--out"),
    "export: an existing --out": (
        ["export", "--checkpoint", "{garbage.pt}", "--out", "{garbage.onnx}"],
        "--force",
    ),
    "unknown command": (["fly"], "unknown command"),
    "unknown option": (_repeat("--speed", "3"), "--speed"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_bad_input_is_one_line_and_exit_code_2(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv, words = CASES[name]
    subs = _inputs(tmp_path)
    given = {Path(p).name for p in subs.values()}
    argv = [subs.get(a, a).replace("{tmp}", str(tmp_path)) for a in argv]
    code, line = _in_process(capsys, argv)
    assert code == 2, line
    assert words in line and "allow_pickle" not in line
    left = sorted(p.name for p in tmp_path.iterdir() if p.name not in given)
    assert left == [], f"{name} left {left} behind"


def _subprocess(
    args: list[str], block: tuple[str, ...] = (), timeout: float = 60
) -> subprocess.CompletedProcess:
    prelude = (
        f"import sys\nfor n in {block!r}:\n    sys.modules[n] = None\n"
        "from vtr.cli import main\nsys.exit(main(sys.argv[1:]))\n"
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, "-c", prelude, *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def test_nothing_answering_is_one_line_in_bounded_time(tmp_path: Path) -> None:
    out = tmp_path / "t.npz"
    args = ["teach", "--sim", NO_SERVER, "--route", ROUTE_JSON, "--out", str(out), "--timeout", "0.2"]
    proc = _subprocess([*args, "--retries", "2"], timeout=30)
    assert proc.returncode == 2 and "no reply" in _one_line(proc.stderr)
    assert not out.exists()


def test_a_busy_port_is_one_line(tmp_path: Path) -> None:
    from vtr.sim2d.server import ServerThread
    from vtr.sim2d.simulator import Simulator

    with ServerThread(Simulator()) as server:
        proc = _subprocess(["sim", "serve", "--bind", server.endpoint], timeout=30)
    assert proc.returncode == 2 and "--bind" in _one_line(proc.stderr)


def test_demo_on_the_robot_board_install_says_what_to_install(tmp_path: Path) -> None:
    proc = _subprocess(
        ["demo", "--out", str(tmp_path / "demo")], block=("pymunk", "cv2", "torch"), timeout=60
    )
    assert proc.returncode == 2 and "pip install 'vtr-mpc[sim]'" in _one_line(proc.stderr)
    assert not (tmp_path / "demo").exists()


def test_the_robot_board_entry_refuses_a_bad_address_in_one_line() -> None:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    code = "import sys\nfrom vtr.runtime.cli import main\nsys.exit(main(sys.argv[1:]))\n"
    args = ["repeat", "--sim", "tcp://127.0.0.1", "--model", MODEL, "--route", "r.npz"]
    proc = subprocess.run(
        [sys.executable, "-c", code, *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=30
    )
    assert proc.returncode == 2 and "no port" in _one_line(proc.stderr)


@pytest.mark.parametrize("example", ["minimal_robot_server.py", "apartment_robot_server.py"])
def test_an_example_robot_on_a_busy_port_is_one_line(example: str) -> None:
    import socket

    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        address = f"tcp://127.0.0.1:{busy.getsockname()[1]}"
        proc = subprocess.run(
            [sys.executable, str(ROOT / "examples" / example), "--bind", address],
            capture_output=True,
            text=True,
            timeout=30,
        )
    assert proc.returncode == 2 and f"cannot bind --bind {address}: Address already in use" in _one_line(
        proc.stderr
    )
