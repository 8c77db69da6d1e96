"""The machine's reference figures: its core count and its float32 matrix-multiply rate (onnxruntime in
process, numpy in a subprocess whose BLAS is pinned to the thread count: ``benchmarks/matmul_probe.py``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

from vtr.benchmarks.timing import time_call


def all_cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


# ---------------------------------------------------------------- inputs


def ort_session(path: Path, threads: int) -> Any:
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    return ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])


# ---------------------------------------------------------------- hardware reference


def matmul_rate_ort(n: int, threads: int, steps: int = 20) -> float:
    """Median GFLOP/s of an n x n x n float32 MatMul in onnxruntime (the engine that runs the model)."""
    import onnx
    import onnxruntime as ort
    from onnx import TensorProto, helper, numpy_helper

    rng = np.random.default_rng(0)
    b = numpy_helper.from_array(rng.standard_normal((n, n)).astype(np.float32), "B")
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["A", "B"], ["C"])],
        "matmul",
        [helper.make_tensor_value_info("A", TensorProto.FLOAT, [n, n])],
        [helper.make_tensor_value_info("C", TensorProto.FLOAT, [n, n])],
        [b],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    sess = ort.InferenceSession(model.SerializeToString(), opts, providers=["CPUExecutionProvider"])
    a = rng.standard_normal((n, n)).astype(np.float32)
    t = time_call(lambda: sess.run(None, {"A": a}), steps, 3)
    del onnx
    return 2.0 * n**3 / (t["p50_ms"] / 1e3) / 1e9


def matmul_rate_numpy(n: int, threads: int, steps: int = 20) -> float | None:
    """Median GFLOP/s of numpy's float32 matmul in a subprocess whose BLAS is pinned to `threads` threads."""
    env = {}
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS"):
        env[var] = str(threads)
    try:
        out = subprocess.run(
            [sys.executable, "-m", "vtr.benchmarks.matmul_probe", str(n), str(steps)],
            env=child_env(env),
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        )
        return float(json.loads(out.stdout.strip().splitlines()[-1])["gflops"])
    except (subprocess.SubprocessError, ValueError, KeyError, IndexError):
        return None


def child_env(extra: dict[str, str] | None = None) -> dict[str, str]:
    """The environment for a ``python -m vtr...`` probe: this ``vtr`` importable, plus ``extra``."""
    import vtr

    root = str(Path(vtr.__file__).resolve().parent.parent)
    env = dict(os.environ, **(extra or {}))
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH", "")) if p)
    return env
