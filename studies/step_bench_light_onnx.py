"""`python -m studies.step_bench_light_onnx` (from the checkout's root): would light matching be cheaper
inside the ONNX graph?

Issue 11 asked whether fusing the runtime's light matching (runtime/light.py) into the network's
onnxruntime call would cut the step's overhead. This builds that subgraph with onnx.helper (uint8 camera
image in, the network's float32 (1, 3, H, W) input out; planar, so every broadcast runs over contiguous
rows) and times it, interleaved, against the numpy path the runtime runs (``LightMatchedPolicy.match``
plus the scaling into the tensor), on one thread. It also reports how many tensor values differ (Log, Exp
and the reductions round differently in onnxruntime). Prints one JSON line. A probe, not a test: nothing
here asserts a time.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np

H_DEFAULT = 128


def light_graph(height: int, width: int) -> Any:
    """The ONNX model: inputs current_u8 (1, H, W, 3) uint8, ref_cols (1, 1, 1, W) (subgoal column means
    + 1), ref_mean and ref_std (1, 3, 1, 1); output current (1, 3, H, W) float32 in [0, 1]."""
    from onnx import TensorProto, helper, numpy_helper

    nodes: list[Any] = []

    def op(kind: str, inputs: list[str], out: str, **attrs: Any) -> str:
        nodes.append(helper.make_node(kind, inputs, [out], **attrs))
        return out

    x_axis = np.linspace(-1.0, 1.0, width, dtype=np.float32)
    consts = {
        "axes_cw": np.array([1, 2], np.int64),
        "axes_hw": np.array([2, 3], np.int64),
        "three": np.float32(3),
        "height": np.float32(height),
        "one": np.float32(1),
        "half": np.float32(0.5),
        "zero": np.float32(0),
        "top": np.float32(255),
        "x": x_axis.reshape(1, 1, 1, width),
        "xx": np.float32((x_axis * x_axis).sum()),
        "pixels": np.float32(height * width),
        "floor": np.float32(2),
        "scale": np.float32(1 / 255),
    }
    inits = [numpy_helper.from_array(np.asarray(v), k) for k, v in consts.items()]
    p = op(
        "Cast", [op("Transpose", ["current_u8"], "planar_u8", perm=[0, 3, 1, 2])], "p", to=TensorProto.FLOAT
    )
    cols = op(
        "Div",
        [op("Div", [op("ReduceSum", [p, "axes_cw"], "colsum", keepdims=1), "three"], "c3"), "height"],
        "cols",
    )
    log_ratio = op("Log", [op("Div", ["ref_cols", op("Add", [cols, "one"], "cols1")], "ratio")], "log_ratio")
    centred = op("Sub", [log_ratio, op("ReduceMean", [log_ratio], "lr_mean", keepdims=1)], "centred")
    slope = op("Div", [op("ReduceSum", [op("Mul", ["x", centred], "xc")], "num", keepdims=1), "xx"], "slope")
    gain = op("Exp", [op("Mul", [slope, "x"], "sx")], "gain")
    ramped = op("Add", [op("Mul", [p, gain], "pg"), "half"], "pg_half")
    levels = op("Floor", [op("Clip", [ramped, "zero", "top"], "ramp_clipped")], "levels")
    mean = op("Div", [op("ReduceSum", [levels, "axes_hw"], "sum", keepdims=1), "pixels"], "mean")
    square_mean = op(
        "Div", [op("ReduceSumSquare", [levels], "sumsq", axes=[2, 3], keepdims=1), "pixels"], "sq"
    )
    var = op("Max", [op("Sub", [square_mean, op("Mul", [mean, mean], "m2")], "v0"), "zero"], "var")
    std = op("Max", [op("Sqrt", [var], "sd0"), "floor"], "std")
    g = op("Div", ["ref_std", std], "g")
    shift = op("Add", [op("Sub", ["ref_mean", op("Mul", [mean, g], "mg")], "sh0"), "half"], "shift")
    matched = op("Add", [op("Mul", [levels, g], "lg"), shift], "matched")
    out = op("Floor", [op("Clip", [matched, "zero", "top"], "matched_clipped")], "matched_levels")
    op("Mul", [out, "scale"], "current")
    inputs = [
        helper.make_tensor_value_info("current_u8", TensorProto.UINT8, [1, height, width, 3]),
        helper.make_tensor_value_info("ref_cols", TensorProto.FLOAT, [1, 1, 1, width]),
        helper.make_tensor_value_info("ref_mean", TensorProto.FLOAT, [1, 3, 1, 1]),
        helper.make_tensor_value_info("ref_std", TensorProto.FLOAT, [1, 3, 1, 1]),
    ]
    outputs = [helper.make_tensor_value_info("current", TensorProto.FLOAT, [1, 3, height, width])]
    graph = helper.make_graph(nodes, "light_matching", inputs, outputs, inits)
    return helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])


def run(steps: int, warmup: int, size: int) -> dict[str, Any]:
    import onnxruntime as ort

    from vtr.benchmarks.step_bench import sample_route
    from vtr.benchmarks.timing import time_interleaved
    from vtr.runtime.light import LightMatchedPolicy, LightReference
    from vtr.runtime.preprocess import input_into

    current, route = sample_route(size, size)
    ramp = np.linspace(0.5, 1.1, size, dtype=np.float32)[None, :, None]
    current = np.clip(current * ramp * 0.8 + 10, 0, 255).astype(np.uint8)  # changed light: work to do
    subgoal = route[0]
    options = ort.SessionOptions()
    options.intra_op_num_threads, options.inter_op_num_threads = 1, 1
    model = light_graph(size, size)
    session = ort.InferenceSession(model.SerializeToString(), options, providers=["CPUExecutionProvider"])
    ref = LightReference.of(subgoal)
    feeds = {
        "current_u8": current[None],
        "ref_cols": ref.cols.reshape(1, 1, 1, -1),
        "ref_mean": ref.mean.reshape(1, 3, 1, 1),
        "ref_std": ref.std.reshape(1, 3, 1, 1),
    }
    wrapper = LightMatchedPolicy(None)

    def numpy_path() -> np.ndarray:
        levels = wrapper.match(current, subgoal)
        return input_into(levels, levels)  # scaled in place, as the policy scales into its input buffer

    def onnx_path() -> np.ndarray:
        return session.run(["current"], feeds)[0]

    a, b = numpy_path().copy(), onnx_path()
    times = time_interleaved({"numpy": numpy_path, "onnxruntime": onnx_path}, steps, warmup)
    return {
        "image": [size, size],
        "numpy_p50_ms": times["numpy"]["p50_ms"],
        "onnxruntime_p50_ms": times["onnxruntime"]["p50_ms"],
        "onnx_nodes": len(model.graph.node),
        "values_differing": int((a != b).sum()),
        "max_abs_difference": float(np.abs(a - b).max()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000, help="timed iterations (default: 2000)")
    parser.add_argument("--warmup", type=int, default=200, help="untimed iterations first (default: 200)")
    parser.add_argument("--size", type=int, default=H_DEFAULT, help="image side in pixels (default: 128)")
    args = parser.parse_args(argv)
    print(json.dumps(run(args.steps, args.warmup, args.size)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
