"""One `export_onnx()` for every model we ship: eval mode, named inputs/outputs, explicit opset, full
checker, the model's constants as metadata, parity against torch (raises past the tolerance), atomic write.

VelocityNet's contract (runtime/model_meta.py): inputs ``current`` and ``subgoal`` are float32
(B, 3, H, W) in [0, 1] from ``runtime.preprocess.to_nchw`` (not uint8: preprocessing stays in the one
numpy function, and the same file runs in cv2.dnn); output ``velocities`` (B, 2, N), row 0 = v (m/s),
row 1 = w (rad/s). The batch dimension is dynamic.

We use the TorchScript exporter (``dynamo=False``): for these small CNNs it gives a plain graph of
Conv/LeakyReLU/GlobalAveragePool/Reshape/Tanh/Mul/Concat with BatchNorm folded into the convs, which
cv2.dnn reads. The dynamo exporter (``dynamo=True``) also runs in both runtimes, but it emits opset 18
and fails to down-convert to an explicit lower opset, and it writes ReduceMean for the pooling.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from vtr.runtime.atomic import temp_dir
from vtr.runtime.contracts import CONTROL_DT
from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL, OUTPUT_VELOCITIES, PREFIX, ModelMeta
from vtr.runtime.preprocess import PREPROCESSING

DEFAULT_OPSET = 17  # >= 16 for ViewNet's GridSample; onnxruntime and cv2.dnn both read it
#: Max |onnxruntime - torch| allowed on VelocityNet's output (m/s, rad/s): float32 reordering noise is
#: ~1e-6; anything near 1e-4 would be a real graph difference.
DEFAULT_ATOL = 1e-4


class ParityError(RuntimeError):
    """The exported graph disagrees with the torch model beyond the stated tolerance."""


def _session(path_or_bytes: str | bytes) -> Any:
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    return ort.InferenceSession(path_or_bytes, opts, providers=["CPUExecutionProvider"])


def export_onnx(
    model: torch.nn.Module,
    out_path: str | os.PathLike,
    meta: ModelMeta | Mapping[str, str],
    opset: int = DEFAULT_OPSET,
    sample_inputs: Sequence[torch.Tensor] | None = None,
    real_inputs: Sequence[np.ndarray] | None = None,
    input_names: Sequence[str] = (INPUT_CURRENT, INPUT_SUBGOAL),
    output_names: Sequence[str] = (OUTPUT_VELOCITIES,),
    atol: float = DEFAULT_ATOL,
    dynamo: bool = False,
    seed: int = 0,
    extra_props: Mapping[str, str] | None = None,
) -> dict[str, Any]:
    """Export ``model`` to ``out_path`` and verify it.

    Args:
        model: the torch module (put in eval mode here).
        out_path: the .onnx file, written atomically.
        meta: constants stored as ``vtr.*`` metadata_props: a ``ModelMeta`` (VelocityNet, what the runtime
            reads) or ready props (``viewnet_props``; then ``sample_inputs`` must be given).
        opset: ONNX opset, explicit.
        sample_inputs: tensors to trace with; default: random inputs of the shapes ``meta`` implies
            (two (1, 3, H, W) images, as VelocityNet takes).
        real_inputs: numpy arrays (batched, one per input) from the dataset for the parity check.
        input_names, output_names: ONNX graph names (the runtime contract for VelocityNet).
        atol: max abs difference allowed between onnxruntime and torch; ParityError past it.
        dynamo: use the dynamo exporter instead of the TorchScript one.
        seed: seeds the fresh random parity inputs.
        extra_props: more metadata (export/provenance.py: the recipe and the data summary).

    Returns:
        {"opset", "max_abs_err_random", "max_abs_err_real" (or None), "atol", "bytes"}.
    """
    import onnx

    model = model.eval().cpu()
    props = meta.to_props() if isinstance(meta, ModelMeta) else dict(meta)
    props.update(extra_props or {})
    if sample_inputs is None:
        if not isinstance(meta, ModelMeta):
            raise ValueError("export_onnx needs sample_inputs when meta is not a ModelMeta")
        sample_inputs = tuple(torch.rand(1, 3, meta.image_height, meta.image_width) for _ in input_names)
    sample_inputs = tuple(sample_inputs)
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    dynamic = {name: {0: "batch"} for name in (*input_names, *output_names)}
    with temp_dir(out_path.parent) as tmpdir:  # removed on exit; a kill -9 leftover goes on the next run
        raw = os.path.join(tmpdir, "raw.onnx")
        kwargs: dict[str, Any] = {"dynamo": dynamo}
        if dynamo:
            kwargs["dynamic_shapes"] = {
                name: {0: torch.export.Dim("batch")} for name in _arg_names(model, input_names)
            }
        else:
            kwargs["dynamic_axes"] = dynamic
        with torch.no_grad(), warnings.catch_warnings():
            # The TorchScript exporter is deprecated upstream but still gives the cleanest graph (see above).
            warnings.simplefilter("ignore", DeprecationWarning)
            torch.onnx.export(
                model,
                sample_inputs,
                raw,
                input_names=list(input_names),
                output_names=list(output_names),
                opset_version=opset,
                do_constant_folding=True,
                **kwargs,
            )
        proto = onnx.load(raw)
        del proto.metadata_props[:]
        for key, value in props.items():
            proto.metadata_props.add(key=key, value=value)
        proto.doc_string = "vtr-mpc " + type(model).__name__
        onnx.checker.check_model(proto, full_check=True)
        data = proto.SerializeToString()
        result = {"opset": opset, "atol": atol, "bytes": len(data)}
        rng = np.random.default_rng(seed)
        fresh = [rng.random((2, *t.shape[1:]), dtype=np.float32) for t in sample_inputs]
        result["max_abs_err_random"] = check_parity(model, data, input_names, fresh, atol)
        result["max_abs_err_real"] = (
            check_parity(model, data, input_names, list(real_inputs), atol)
            if real_inputs is not None
            else None
        )
        tmp = os.path.join(tmpdir, "final.onnx")
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, out_path)
    return result


def _arg_names(model: torch.nn.Module, input_names: Sequence[str]) -> list[str]:
    import inspect

    params = list(inspect.signature(model.forward).parameters)
    return params[: len(input_names)]


def check_parity(
    model: torch.nn.Module,
    onnx_model: str | bytes,
    input_names: Sequence[str],
    inputs: Sequence[np.ndarray],
    atol: float,
) -> float:
    """Max |onnxruntime - torch| over the first output; raises ParityError if above ``atol``."""
    sess = _session(onnx_model)
    got = sess.run(None, dict(zip(input_names, inputs, strict=True)))[0]
    with torch.no_grad():
        want = model.eval().cpu()(*[torch.from_numpy(np.ascontiguousarray(x)) for x in inputs])
    err = float(np.abs(got - want.numpy()).max())
    if not err <= atol:
        raise ParityError(f"onnxruntime differs from torch by {err:.3g} > tolerance {atol:.3g}")
    return err


def viewnet_props(cfg: Any, dt: float = CONTROL_DT) -> dict[str, str]:
    """ViewNet's ONNX metadata: what it is and what it was trained on, not VelocityNet's policy contract
    (so the runtime refuses a ViewNet given as a policy: it lacks ``vtr.horizon``)."""
    return {
        PREFIX + "kind": "viewnet",
        PREFIX + "image_height": str(cfg.image_size),
        PREFIX + "image_width": str(cfg.image_size),
        PREFIX + "v_max": str(cfg.v_max),
        PREFIX + "w_max": str(cfg.w_max),
        PREFIX + "dt": str(dt),
        PREFIX + "preprocessing": PREPROCESSING,
    }


def velocitynet_meta(cfg: Any, dt: float = CONTROL_DT, **camera: float) -> ModelMeta:
    """ModelMeta for a VelocityNetConfig; ``camera``: camera_fov_deg / camera_height_m of the training data
    where it recorded them (the defaults are sim2d's camera)."""
    return ModelMeta(
        **camera,
        image_height=cfg.image_size,
        image_width=cfg.image_size,
        horizon=cfg.horizon,
        v_max=cfg.v_max,
        w_max=cfg.w_max,
        dt=dt,
        preprocessing=getattr(cfg, "preprocessing", PREPROCESSING),
    )
