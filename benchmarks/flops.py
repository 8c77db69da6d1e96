"""FLOPs of one forward pass of an ONNX model, from its Conv / Gemm / MatMul nodes (1 MAC = 2 FLOP)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

#: Ops whose multiply-accumulates are counted; everything else (activations, adds) is noise next to them.
COUNTED_OPS = ("Conv", "ConvTranspose", "Gemm", "MatMul", "QLinearConv", "ConvInteger", "MatMulInteger")


def _input_shapes(model: Any) -> dict[str, tuple[int, ...]]:
    """Graph inputs (not initialisers) with symbolic dims replaced by 1."""
    init_names = {t.name for t in model.graph.initializer}
    shapes = {}
    for inp in model.graph.input:
        if inp.name in init_names:
            continue
        dims = [d.dim_value if d.dim_value > 0 else 1 for d in inp.type.tensor_type.shape.dim]
        shapes[inp.name] = tuple(dims)
    return shapes


def count_flops(path: str | Path) -> dict[str, Any]:
    """FLOPs of one forward pass at batch 1, from the graph's Conv / Gemm / MatMul nodes (1 MAC = 2 FLOPs).

    Tensor shapes come from running the graph once in onnxruntime with every counted node's tensors
    exposed as outputs, which works for any graph the runtime can load (shape inference alone gives up on
    some exporter patterns). Returns ``{"gflop": float, "macs_by_op": {op: macs}, "nodes": int}``.
    """
    import onnx
    import onnxruntime as ort

    model = onnx.load(str(path))
    inits = {t.name: tuple(t.dims) for t in model.graph.initializer}
    counted = [nd for nd in model.graph.node if nd.op_type in COUNTED_OPS]
    wanted: list[str] = []
    existing = {o.name for o in model.graph.output}
    for nd in counted:
        tensors = [nd.output[0], nd.input[0]]
        if nd.op_type in ("QLinearConv",):
            tensors.append(nd.input[3])
        elif len(nd.input) > 1:
            tensors.append(nd.input[1])
        for name in tensors:
            if name and name not in inits and name not in wanted:
                wanted.append(name)
    for name in wanted:
        if name not in existing:
            model.graph.output.append(onnx.ValueInfoProto(name=name))
    opts = ort.SessionOptions()
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    opts.intra_op_num_threads = 1
    sess = ort.InferenceSession(model.SerializeToString(), opts, providers=["CPUExecutionProvider"])
    feeds = {}
    for inp in sess.get_inputs():
        shape = _input_shapes(model)[inp.name]
        dtype = np.uint8 if "uint8" in inp.type else np.float32
        feeds[inp.name] = np.zeros(shape, dtype=dtype)
    names = [o.name for o in sess.get_outputs()]
    values = dict(zip(names, sess.run(names, feeds), strict=True))
    shape_of = {**inits, **{k: tuple(v.shape) for k, v in values.items()}}

    macs_by_op: dict[str, int] = {}
    for nd in counted:
        out = shape_of[nd.output[0]]
        if nd.op_type in ("Conv", "ConvInteger", "QLinearConv"):
            wshape = shape_of[
                nd.input[3] if nd.op_type == "QLinearConv" else nd.input[1]
            ]  # (Cout, Cin/g, kh, kw)
            macs = int(np.prod(out)) * int(np.prod(wshape[1:]))
        elif nd.op_type == "ConvTranspose":
            wshape = shape_of[nd.input[1]]  # (Cin, Cout/g, kh, kw)
            inp_shape = shape_of[nd.input[0]]
            macs = int(np.prod(inp_shape)) * int(np.prod(wshape[1:]))
        else:  # Gemm / MatMul: output elements times the reduced dimension
            a = shape_of[nd.input[0]]
            trans_a = any(at.name == "transA" and at.i for at in nd.attribute)
            k = a[-2] if trans_a else a[-1]
            macs = int(np.prod(out)) * int(k)
        macs_by_op[nd.op_type] = macs_by_op.get(nd.op_type, 0) + macs
    return {"gflop": 2.0 * sum(macs_by_op.values()) / 1e9, "macs_by_op": macs_by_op, "nodes": len(counted)}
