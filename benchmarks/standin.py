"""A stand-in VelocityNet ONNX with random weights: the runtime's contract (``runtime.model_meta``: inputs,
output, metadata) without a trained model, so the latency harness and the tests run before one exists."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL, OUTPUT_VELOCITIES, ModelMeta


def make_standin_velocitynet(
    path: str | Path,
    meta: ModelMeta | None = None,
    widths: tuple[int, ...] = (32, 64, 128, 256, 256, 512, 512),
    seed: int = 0,
    opset: int = 17,
) -> Path:
    """Write an ONNX with VelocityNet's signature and a paper-like body (stride-2 3x3 convs + LeakyReLU).

    ``current`` and ``subgoal`` (B, 3, H, W) are concatenated to 6 channels, ``len(widths)`` conv layers
    halve the resolution, a global average pool and a 1x1 conv give 2N numbers, reshaped to (B, 2, N),
    squashed by tanh and scaled by (v_max, w_max). Weights are He-initialised from ``seed``.
    """
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    meta = meta or ModelMeta()
    rng = np.random.default_rng(seed)
    n = meta.horizon
    h, w = meta.image_height, meta.image_width
    nodes = [helper.make_node("Concat", [INPUT_CURRENT, INPUT_SUBGOAL], ["x0"], axis=1)]
    inits = []
    c_in, x = 6, "x0"
    for i, c_out in enumerate((*widths, 2 * n)):
        last = i == len(widths)
        k = 1 if last else 3
        wt = rng.normal(0.0, np.sqrt(2.0 / (c_in * k * k)), size=(c_out, c_in, k, k)).astype(np.float32)
        inits += [
            numpy_helper.from_array(wt, f"w{i}"),
            numpy_helper.from_array(np.zeros(c_out, np.float32), f"b{i}"),
        ]
        if last:
            nodes.append(helper.make_node("GlobalAveragePool", [x], ["pooled"]))
            nodes.append(
                helper.make_node("Conv", ["pooled", f"w{i}", f"b{i}"], ["head"], kernel_shape=[1, 1])
            )
        else:
            nodes.append(
                helper.make_node(
                    "Conv",
                    [x, f"w{i}", f"b{i}"],
                    [f"c{i}"],
                    kernel_shape=[3, 3],
                    strides=[2, 2],
                    pads=[1, 1, 1, 1],
                )
            )
            nodes.append(helper.make_node("LeakyRelu", [f"c{i}"], [f"a{i}"], alpha=0.2))
            x = f"a{i}"
        c_in = c_out
    inits.append(numpy_helper.from_array(np.array([-1, 2, n], np.int64), "shape"))
    inits.append(numpy_helper.from_array(np.array([[meta.v_max], [meta.w_max]], np.float32), "scale"))
    nodes += [
        helper.make_node("Reshape", ["head", "shape"], ["raw"]),
        helper.make_node("Tanh", ["raw"], ["squashed"]),
        helper.make_node("Mul", ["squashed", "scale"], [OUTPUT_VELOCITIES]),
    ]
    graph = helper.make_graph(
        nodes,
        "standin_velocitynet",
        [
            helper.make_tensor_value_info(INPUT_CURRENT, TensorProto.FLOAT, ["B", 3, h, w]),
            helper.make_tensor_value_info(INPUT_SUBGOAL, TensorProto.FLOAT, ["B", 3, h, w]),
        ],
        [helper.make_tensor_value_info(OUTPUT_VELOCITIES, TensorProto.FLOAT, ["B", 2, n])],
        inits,
    )
    model = helper.make_model(
        graph, opset_imports=[helper.make_opsetid("", opset)], producer_name="vtr-bench"
    )
    model.ir_version = 8
    helper.set_model_props(model, {**meta.to_props(), "vtr.standin": "random weights, benchmarks only"})
    onnx.checker.check_model(model, full_check=True)
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    onnx.save(model, str(tmp))
    tmp.replace(path)
    return path
