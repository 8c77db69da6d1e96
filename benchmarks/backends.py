"""The model on every inference backend (onnxruntime fp32 and int8, torch eager, OpenCV cv2.dnn) at a
thread count, beside the machine's matmul rate. Torch eager times the real ``training.models.VelocityNet``
(from ``--checkpoint``, or built with the ONNX model's layer widths: weights do not change its time)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from vtr.benchmarks.hardware import all_cores, matmul_rate_numpy, matmul_rate_ort, ort_session
from vtr.benchmarks.timing import time_interleaved

if TYPE_CHECKING:
    from vtr.benchmarks.latency import LatencyConfig


def _backend_runner(
    name: str, cfg: LatencyConfig, threads: int, x: np.ndarray, y: np.ndarray
) -> Callable[[], Any]:
    """A zero-argument callable running one inference of the model on the given backend."""
    from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL

    if name in ("ort_fp32", "ort_int8"):
        path = cfg.model if name == "ort_fp32" else cfg.int8_model
        if path is None:
            raise FileNotFoundError(
                "no int8 model (pass --int8-model or put <model>-int8.onnx beside the model)"
            )
        sess = ort_session(Path(path), threads)
        feeds = {INPUT_CURRENT: x, INPUT_SUBGOAL: y}
        return lambda: sess.run(None, feeds)
    if name == "torch_eager":
        import torch

        torch.set_num_threads(threads)
        module = _torch_module(cfg)
        tx, ty = torch.from_numpy(x), torch.from_numpy(y)

        def run_torch() -> Any:
            with torch.inference_mode():
                return module(tx, ty)

        return run_torch
    if name == "cv2_dnn":
        import cv2

        cv2.setNumThreads(threads)
        net = cv2.dnn.readNetFromONNX(str(cfg.model))

        def run_cv2() -> Any:
            net.setInput(x, INPUT_CURRENT)
            net.setInput(y, INPUT_SUBGOAL)
            return net.forward()

        return run_cv2
    raise ValueError(f"unknown backend {name!r}")


def _torch_module(cfg: LatencyConfig) -> Callable[[Any, Any], Any]:
    """The real VelocityNet nn.Module in eval mode: from ``--checkpoint``, else built with the layer widths
    of the ONNX model (random weights: the time of a forward pass does not depend on them)."""
    if cfg.checkpoint is not None:
        from vtr.training.checkpoint import load_model

        kind, net, _ = load_model(cfg.checkpoint)
        if kind != "velocitynet":
            raise ValueError(f"{cfg.checkpoint} holds a {kind}, not a velocitynet")
    else:
        net = velocitynet_like(cfg.model)
    return lambda a, b: net(a, b)


def velocitynet_like(path: Path) -> Any:
    """``training.models.VelocityNet`` with the ONNX model's widths, horizon and image size."""
    import onnx

    from vtr.training.config import VelocityNetConfig
    from vtr.training.models import VelocityNet

    model = onnx.load(str(path))
    inits = {t.name: tuple(t.dims) for t in model.graph.initializer}
    widths = [inits[n.input[1]][0] for n in model.graph.node if n.op_type == "Conv" and n.input[1] in inits]
    shape = [d.dim_value for d in model.graph.input[0].type.tensor_type.shape.dim]
    if len(widths) != 8 or widths[-1] % 2:
        raise ValueError(
            f"{path} does not have VelocityNet's 8 convolutions; pass --checkpoint for torch eager"
        )
    cfg = VelocityNetConfig(image_size=int(shape[-1]), channels=tuple(widths[:7]), horizon=widths[-1] // 2)
    return VelocityNet(cfg).eval()


def bench_backends(cfg: LatencyConfig, x: np.ndarray, y: np.ndarray, gflop: float) -> dict[str, Any]:
    """Every backend at every thread count, plus the matmul reference at the same thread counts."""
    results: dict[str, Any] = {"threads": {}}
    for t in cfg.thread_counts:
        threads = t or all_cores()
        entry: dict[str, Any] = {"matmul": {}, "backends": {}}
        ort_rate = matmul_rate_ort(cfg.matmul_size, threads)
        np_rate = matmul_rate_numpy(cfg.matmul_size, threads)
        entry["matmul"] = {
            "n": cfg.matmul_size,
            "ort_gflops": ort_rate,
            "numpy_gflops": np_rate,
            "best_gflops": max(r for r in (ort_rate, np_rate) if r is not None),
        }
        runners: dict[str, Callable[[], Any]] = {}
        for name in cfg.backends:
            try:
                runners[name] = _backend_runner(name, cfg, threads, x, y)
                runners[name]()
            except Exception as err:  # a backend that cannot load this model is reported, not fatal
                runners.pop(name, None)
                entry["backends"][name] = {"skipped": f"{type(err).__name__}: {err}"}
        timings = time_interleaved(runners, cfg.steps, cfg.warmup)
        for name, timing in timings.items():
            achieved = gflop / (timing["p50_ms"] / 1e3)
            entry["backends"][name] = {
                **timing,
                "gflop_per_step": gflop,
                "achieved_gflops": achieved,
                "fraction_of_matmul": achieved / entry["matmul"]["best_gflops"],
            }
        results["threads"][str(threads)] = entry
    return results
