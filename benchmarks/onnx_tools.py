"""ONNX helpers for the benchmarks: a stand-in VelocityNet, a FLOP counter, and a torch-eager rebuild.

The stand-in lets the latency harness and its tests run before a trained model exists: same inputs,
output and metadata as the runtime's contract (`runtime.model_meta`), random weights. The torch
rebuild runs an ONNX graph op by op with torch functions, which is what an eager ``nn.Module``
forward does, so it serves as the "torch eager" backend when no checkpoint is at hand.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL, OUTPUT_VELOCITIES, ModelMeta

#: Ops whose multiply-accumulates are counted; everything else (activations, adds) is noise next to them.
COUNTED_OPS = ("Conv", "ConvTranspose", "Gemm", "MatMul", "QLinearConv", "ConvInteger", "MatMulInteger")


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


class OnnxTorchModule:
    """Runs an fp32 ONNX graph node by node with torch ops (an eager forward built from the ONNX weights)."""

    def __init__(self, path: str | Path) -> None:
        import onnx
        import torch
        from onnx import numpy_helper

        model = onnx.load(str(path))
        self.graph = model.graph
        self.consts: dict[str, torch.Tensor] = {
            t.name: torch.from_numpy(numpy_helper.to_array(t).copy()) for t in model.graph.initializer
        }
        self.inputs = [i.name for i in model.graph.input if i.name not in self.consts]
        self.outputs = [o.name for o in model.graph.output]
        self.nodes = list(model.graph.node)
        if not _TORCH_OPS:
            _TORCH_OPS.update(_build_torch_ops())
        for nd in self.nodes:
            if nd.op_type not in _TORCH_OPS:
                raise NotImplementedError(f"ONNX op {nd.op_type!r} has no torch eager mapping here")
        # Parse attributes once, as a module's __init__ would.
        self.attrs = [{a.name: onnx.helper.get_attribute_value(a) for a in nd.attribute} for nd in self.nodes]

    def __call__(self, **feeds: Any) -> list[Any]:
        env = dict(self.consts)
        env.update(feeds)
        for nd, attrs in zip(self.nodes, self.attrs, strict=True):
            args = [env[name] if name else None for name in nd.input]
            out = _TORCH_OPS[nd.op_type](args, attrs)
            if not isinstance(out, tuple):
                out = (out,)
            env.update(zip(nd.output, out, strict=False))
        return [env[name] for name in self.outputs]


def _conv(args: list[Any], at: dict[str, Any]) -> Any:
    import torch.nn.functional as F

    x, w = args[0], args[1]
    b = args[2] if len(args) > 2 else None
    pads = at.get("pads", [0, 0, 0, 0])
    if pads[0] != pads[2] or pads[1] != pads[3]:
        x = F.pad(x, (pads[1], pads[3], pads[0], pads[2]))
        pads = [0, 0, 0, 0]
    return F.conv2d(
        x, w, b, stride=at.get("strides", [1, 1]), padding=(pads[0], pads[1]), dilation=at.get("dilations", [1, 1]),
        groups=at.get("group", 1),
    )  # fmt: skip


def _gemm(args: list[Any], at: dict[str, Any]) -> Any:
    a, b = args[0], args[1]
    if at.get("transA", 0):
        a = a.t()
    if at.get("transB", 0):
        b = b.t()
    y = at.get("alpha", 1.0) * (a @ b)
    if len(args) > 2 and args[2] is not None:
        y = y + at.get("beta", 1.0) * args[2]
    return y


def _reshape(args: list[Any], at: dict[str, Any]) -> Any:
    x, shape = args[0], [int(s) for s in args[1].tolist()]
    shape = [x.shape[i] if s == 0 and not at.get("allowzero", 0) else s for i, s in enumerate(shape)]
    return x.reshape(shape)


def _slice(args: list[Any], at: dict[str, Any]) -> Any:
    x = args[0]
    starts, ends = args[1].tolist(), args[2].tolist()
    axes = args[3].tolist() if len(args) > 3 and args[3] is not None else list(range(len(starts)))
    steps = args[4].tolist() if len(args) > 4 and args[4] is not None else [1] * len(starts)
    index = [slice(None)] * x.dim()
    for s, e, a, st in zip(starts, ends, axes, steps, strict=True):
        index[a] = slice(s, min(e, x.shape[a]) if e > 0 else e, st)
    return x[tuple(index)]


def _split(args: list[Any], at: dict[str, Any]) -> Any:
    x, axis = args[0], at.get("axis", 0)
    sizes = args[1].tolist() if len(args) > 1 and args[1] is not None else at.get("split")
    if sizes is None:
        n = at["num_outputs"]
        sizes = [x.shape[axis] // n] * n
    return tuple(x.split(sizes, dim=axis))


def _batchnorm(args: list[Any], at: dict[str, Any]) -> Any:
    import torch.nn.functional as F

    x, scale, bias, mean, var = args[:5]
    return F.batch_norm(x, mean, var, scale, bias, training=False, eps=at.get("epsilon", 1e-5))


def _build_torch_ops() -> dict[str, Any]:
    """The op table, built once torch is imported (the first OnnxTorchModule)."""
    import torch
    import torch.nn.functional as F
    from onnx import numpy_helper

    def gather(args: list[Any], at: dict[str, Any]) -> Any:
        x, idx, axis = args[0], args[1], at.get("axis", 0)
        out = torch.index_select(x, axis, idx.reshape(-1))
        return out.reshape(*x.shape[:axis], *idx.shape, *x.shape[axis + 1 :])

    def unsqueeze(args: list[Any], at: dict[str, Any]) -> Any:
        axes = args[1].tolist() if len(args) > 1 else at["axes"]
        return args[0].reshape(_unsqueezed_shape(args[0].shape, axes))

    def squeeze(args: list[Any], at: dict[str, Any]) -> Any:
        axes = args[1].tolist() if len(args) > 1 else at.get("axes")
        if axes is None:
            return args[0].squeeze()
        keep = [s for i, s in enumerate(args[0].shape) if i not in {a % args[0].dim() for a in axes}]
        return args[0].reshape(keep)

    return {
        "Conv": _conv,
        "Gemm": _gemm,
        "Reshape": _reshape,
        "Slice": _slice,
        "Split": _split,
        "BatchNormalization": _batchnorm,
        "Relu": lambda a, at: F.relu(a[0]),
        "LeakyRelu": lambda a, at: F.leaky_relu(a[0], at.get("alpha", 0.01)),
        "Tanh": lambda a, at: torch.tanh(a[0]),
        "Sigmoid": lambda a, at: torch.sigmoid(a[0]),
        "Add": lambda a, at: a[0] + a[1],
        "Sub": lambda a, at: a[0] - a[1],
        "Mul": lambda a, at: a[0] * a[1],
        "Div": lambda a, at: a[0] / a[1],
        "MatMul": lambda a, at: a[0] @ a[1],
        "Concat": lambda a, at: torch.cat(a, dim=at["axis"]),
        "Flatten": lambda a, at: a[0].flatten(at.get("axis", 1)),
        "Transpose": lambda a, at: a[0].permute(*at["perm"]),
        "GlobalAveragePool": lambda a, at: a[0].mean(dim=(2, 3), keepdim=True),
        "Identity": lambda a, at: a[0],
        "Constant": lambda a, at: torch.from_numpy(numpy_helper.to_array(at["value"]).copy()),
        "Shape": lambda a, at: torch.tensor(a[0].shape, dtype=torch.int64),
        "Gather": gather,
        "Unsqueeze": unsqueeze,
        "Squeeze": squeeze,
        "Cast": lambda a, at: a[0],
    }


def _unsqueezed_shape(shape: Any, axes: list[int]) -> list[int]:
    out = list(shape)
    rank = len(out) + len(axes)
    for a in sorted(a % rank for a in axes):
        out.insert(a, 1)
    return out


_TORCH_OPS: dict[str, Any] = {}
