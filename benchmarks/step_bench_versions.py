"""`python -m vtr.benchmarks.step_bench_versions BASE_DIR ROUTE.npz MODEL`: ``Repeater.step`` of two code
versions stepped alternately in one process, so that load from other processes hits both alike.

BASE_DIR is another checkout (``git archive REV | tar -x -C BASE_DIR``). Its code is copied to a temporary
folder as the package ``vtr_base`` (every ``vtr.`` import renamed), so it imports beside this checkout's
``vtr``. Each version steps the raw-error, patch-matching and light-matching repeaters of
``step_bench_ab`` on the same saved frames (``step_bench_ab --write``): variant by variant, the two
versions' repeaters alternately, the order reversed every step. Prints one JSON line: per variant the
medians in microseconds of each version and new / base - 1. Differences of a few microseconds between runs of separate processes were the size of
the changes measured here; within one process they repeat to about 1 us.
"""

from __future__ import annotations

import argparse
import importlib
import json
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

VARIANTS = ("raw", "patch", "light")
_IMPORT = re.compile(r"\bvtr\.(runtime|benchmarks|models)\b")


def _renamed_copy(base: Path, into: Path) -> None:
    """``base``'s runtime/ and benchmarks/ (and vtr/models.py) as package ``vtr_base`` under ``into``."""
    pkg = into / "vtr_base"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    for name in ("runtime", "benchmarks"):
        shutil.copytree(base / name, pkg / name, ignore=shutil.ignore_patterns("__pycache__"))
    if (base / "vtr" / "models.py").is_file():
        shutil.copy(base / "vtr" / "models.py", pkg / "models.py")
    for path in pkg.rglob("*.py"):
        path.write_text(_IMPORT.sub(r"vtr_base.\1", path.read_text()))


def medians(base: Path, route_file: str, model: str, steps: int, warmup: int) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        _renamed_copy(base, Path(tmp))
        sys.path.insert(0, tmp)
        try:
            old = importlib.import_module("vtr_base.benchmarks.step_bench_ab")
        finally:
            sys.path.remove(tmp)
        new = importlib.import_module("vtr.benchmarks.step_bench_ab")
        reps = {f"{side}.{name}": rep for side, mod in (("base", old), ("new", new))
                for name, rep in mod._repeaters(route_file, model).items()}  # fmt: skip
    out: dict[str, Any] = {}
    for variant in VARIANTS:  # one pair at a time: six sessions stepped in turn do not fit in the cache
        pair = {side: reps[f"{side}.{variant}"] for side in ("base", "new")}
        samples: dict[str, list[int]] = {side: [] for side in pair}
        for i in range(warmup + steps):
            for side in ("base", "new") if i % 2 == 0 else ("new", "base"):
                t0 = time.perf_counter_ns()
                record = pair[side].step()
                elapsed = time.perf_counter_ns() - t0
                if not record.commanded:
                    raise RuntimeError(f"{side} {variant}: the repeat ended ({record.status})")
                if i >= warmup:
                    samples[side].append(elapsed)
        base_us, new_us = (float(np.median(samples[side])) / 1e3 for side in ("base", "new"))
        out[variant] = {"base_us": round(base_us, 1), "new_us": round(new_us, 1),
                        "change": round(new_us / base_us - 1.0, 4)}  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("base", type=Path, help="the other checkout (git archive REV | tar -x -C BASE)")
    parser.add_argument("route_file", help="ROUTE.npz from step_bench_ab --write")
    parser.add_argument("model", help="VelocityNet ONNX")
    parser.add_argument("--steps", type=int, default=2000, help="timed steps per repeater (default: 2000)")
    parser.add_argument("--warmup", type=int, default=200, help="untimed steps first (default: 200)")
    args = parser.parse_args(argv)
    if not (args.base / "runtime" / "repeater.py").is_file():
        parser.error(f"{args.base} is not a checkout with runtime/repeater.py")
    print(json.dumps(medians(args.base, args.route_file, args.model, args.steps, args.warmup)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
