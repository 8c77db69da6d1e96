"""int8 VelocityNet: onnxruntime static QDQ quantisation, per-channel weights, calibrated on real frames.

The calibration inputs are (current, subgoal) pairs drawn from the dataset the way the runtime meets
them: a frame and a frame a few steps later in the same episode, preprocessed by ``to_nchw``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime.atomic import temp_dir
from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL
from vtr.runtime.preprocess import PREPROCESSING, to_nchw


def calibration_pairs(
    images: np.ndarray,
    episodes: np.ndarray,
    count: int = 128,
    max_gap: int = 4,
    seed: int = 0,
    preprocessing: str = PREPROCESSING,
) -> tuple[np.ndarray, np.ndarray]:
    """(current, subgoal) float32 (count, 3, H, W) each: frame t and frame t+g, 1 <= g <= max_gap, same episode."""
    rng = np.random.default_rng(seed)
    t = len(images)
    cur, sub = [], []
    for _ in range(50 * count):
        if len(cur) == count:
            break
        i = int(rng.integers(0, t))
        j = min(t - 1, i + int(rng.integers(1, max_gap + 1)))
        if episodes[i] == episodes[j]:
            cur.append(i)
            sub.append(j)
    if not cur:
        raise ValueError("no calibration pairs: the dataset has no two frames in one episode")
    return to_nchw(images[cur], preprocessing), to_nchw(images[sub], preprocessing)


class FrameReader:
    """onnxruntime CalibrationDataReader over real (current, subgoal) pairs, one pair per call."""

    def __init__(self, current: np.ndarray, subgoal: np.ndarray) -> None:
        self.current, self.subgoal = current, subgoal
        self._it: Iterator[dict[str, np.ndarray]] | None = None
        self.rewind()

    def get_next(self) -> dict[str, np.ndarray] | None:
        return next(self._it, None)  # type: ignore[arg-type]

    def rewind(self) -> None:
        self._it = (
            {INPUT_CURRENT: self.current[k : k + 1], INPUT_SUBGOAL: self.subgoal[k : k + 1]}
            for k in range(len(self.current))
        )


def quantize_int8(
    fp32_path: str | os.PathLike, out_path: str | os.PathLike, current: np.ndarray, subgoal: np.ndarray
) -> None:
    """Static QDQ int8 (per-channel weights, int8 activations) calibrated on the given pairs; atomic write."""
    import onnx
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    class _Reader(FrameReader, CalibrationDataReader):
        pass

    out_path = Path(out_path)
    with temp_dir(out_path.parent) as tmpdir:  # a kill -9 leftover is removed by the next run
        pre = os.path.join(tmpdir, "pre.onnx")
        quant_pre_process(str(fp32_path), pre, skip_symbolic_shape=True)
        tmp = os.path.join(tmpdir, "int8.onnx")
        quantize_static(
            pre,
            tmp,
            _Reader(current, subgoal),
            quant_format=QuantFormat.QDQ,
            per_channel=True,
            activation_type=QuantType.QInt8,
            weight_type=QuantType.QInt8,
        )
        # quantize_static keeps the graph but not always the metadata: copy ours over.
        src, dst = onnx.load(str(fp32_path)), onnx.load(tmp)
        del dst.metadata_props[:]
        for p in src.metadata_props:
            dst.metadata_props.add(key=p.key, value=p.value)
        onnx.checker.check_model(dst, full_check=True)
        onnx.save(dst, tmp)
        os.replace(tmp, out_path)


def compare(
    fp32_path: str | os.PathLike,
    int8_path: str | os.PathLike,
    current: np.ndarray,
    subgoal: np.ndarray,
    repeats: int = 50,
) -> dict[str, Any]:
    """Output error of int8 against fp32 on the given pairs, and single-thread batch-1 latency of both."""
    import onnxruntime as ort

    def session(path: str | os.PathLike) -> Any:
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = 1
        return ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])

    fp, q = session(fp32_path), session(int8_path)
    feed = {INPUT_CURRENT: current, INPUT_SUBGOAL: subgoal}
    a, b = fp.run(None, feed)[0], q.run(None, feed)[0]
    err = np.abs(a - b)  # (B, 2, N)

    def latency(sess: Any) -> float:
        one = {INPUT_CURRENT: current[:1], INPUT_SUBGOAL: subgoal[:1]}
        for _ in range(5):
            sess.run(None, one)
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            sess.run(None, one)
            times.append(time.perf_counter() - t)
        return float(np.median(times) * 1e3)

    t_fp, t_q = latency(fp), latency(q)
    return {
        "pairs": int(len(current)),
        "max_abs_err_v": float(err[:, 0].max()),
        "max_abs_err_w": float(err[:, 1].max()),
        "mean_abs_err_v": float(err[:, 0].mean()),
        "mean_abs_err_w": float(err[:, 1].mean()),
        "fp32_ms": t_fp,
        "int8_ms": t_q,
        "speedup": t_fp / t_q if t_q > 0 else float("nan"),
    }
