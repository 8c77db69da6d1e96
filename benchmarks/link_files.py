"""`vtr bench link files`: crafted files against the loaders: does any run code, and how much memory does
loading (or refusing) take compared with the file's size?

Each case loads in a fresh Python process: imports first, then the peak-RSS counter is reset
(``/proc/self/clear_refs``), then the load; the figure is peak RSS during the load minus RSS before it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

import vtr

REPO = Path(vtr.__file__).resolve().parents[1]

PROBE = r"""
import json, sys
from vtr.runtime.route import Route
from vtr.runtime.policy import OnnxPolicy
from vtr.training.dataset import load_dataset
kind, path = sys.argv[1], sys.argv[2]
def status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) * 1024
open("/proc/self/clear_refs", "w").write("5")  # reset the peak (VmHWM) to the current RSS
before = status("VmRSS:")
try:
    {"route": Route.load, "model": OnnxPolicy, "dataset": load_dataset}[kind](path)
    refused = ""
except Exception as exc:
    refused = f"{type(exc).__name__}: {exc}"[:160]
print(json.dumps({"refused": refused, "peak_growth": status("VmHWM:") - before}))
"""

MARKER = "code_ran.txt"


class _Payload:
    """Unpickling this runs a shell command: the canary for 'never runs code'."""

    def __init__(self, target: str) -> None:
        self.target = target

    def __reduce__(self) -> tuple[Any, ...]:
        return (os.system, (f"touch {self.target}",))


def _route_arrays(n: int, side: int) -> dict[str, np.ndarray]:
    meta = {"format_version": 1, "name": "crafted", "camera": {}, "spacing": {}, "map": None, "dt": 0.1}
    return {
        "images": np.zeros((n, side, side, 3), np.uint8),
        "poses": np.zeros((n, 3)),
        "commands": np.zeros((n, 2)),
        "meta": np.array(json.dumps(meta)),
    }


def _cases(folder: Path) -> dict[str, tuple[str, Path]]:
    from vtr.runtime.route import Route

    cases: dict[str, tuple[str, Path]] = {}
    bomb = folder / "bomb_route.npz"
    np.savez_compressed(bomb, **_route_arrays(6000, 128))  # 295 MB of zeros, a few hundred kB on disk
    cases["route: zip bomb"] = ("route", bomb)
    pickled = folder / "pickled_route.npz"
    arrays = _route_arrays(2, 16)
    arrays["meta"] = np.array([_Payload(str(folder / MARKER))], dtype=object)
    np.savez(pickled, **arrays)
    cases["route: pickled object that runs a command"] = ("route", pickled)
    honest = folder / "honest_route.npz"
    Route(**{k: v for k, v in _route_arrays(100, 128).items() if k != "meta"}).save(honest)
    cases["route: an honest 100-subgoal route"] = ("route", honest)
    data = {
        "images": np.zeros((6000, 128, 128, 3), np.uint8),
        "commands": np.zeros((6000, 2), np.float32),
        "poses": np.zeros((6000, 3), np.float32),
        "episodes": np.zeros(6000, np.int32),
        "meta": np.array(json.dumps({"format_version": 1})),
    }
    data_bomb = folder / "bomb_dataset.npz"
    np.savez_compressed(data_bomb, **data)
    cases["dataset: zip bomb"] = ("dataset", data_bomb)
    data_pickle = folder / "pickled_dataset.npz"
    small = {k: v[:4] for k, v in data.items() if k != "meta"}
    np.savez(data_pickle, **small, meta=np.array([_Payload(str(folder / MARKER))], dtype=object))
    cases["dataset: pickled object that runs a command"] = ("dataset", data_pickle)
    model = folder / "huge.onnx"
    with open(model, "wb") as f:
        f.truncate(300 * 1024 * 1024)  # sparse: 300 MiB on paper
    cases["model: 300 MiB file"] = ("model", model)
    return cases


def files() -> dict[str, Any]:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    results: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name, (kind, path) in _cases(folder).items():
            out = subprocess.run(
                [sys.executable, "-c", PROBE, kind, str(path)],
                env=env,
                capture_output=True,
                text=True,
                timeout=300,
            )
            if out.returncode != 0:
                results[name] = {"probe_failed": out.stderr.strip().splitlines()[-1:]}
                continue
            probe = json.loads(out.stdout.strip().splitlines()[-1])
            size = path.stat().st_size  # the model is a sparse file: 300 MiB long, nothing on disk
            results[name] = {
                "file_bytes": size,
                "refused": probe["refused"] or None,
                "peak_growth_mb": round(probe["peak_growth"] / 1e6, 2),
                "growth_over_file_size": round(probe["peak_growth"] / max(size, 1), 2),
            }
        results["code_ran"] = (folder / MARKER).exists()
    return results
