"""`vtr export`: a VelocityNet checkpoint -> ONNX (fp32, optionally int8), with its metadata and checks.

    vtr export --checkpoint runs/default/velocitynet/model.pt --out models/velocitynet.onnx --force \
        [--int8 --data data/house.npz] [--viewnet runs/default/viewnet/model.pt --viewnet-out models/viewnet.onnx]
        [--camera-range 65-105,0.2-0.45]

The int8 model goes next to the fp32 one as ``<name>-int8.onnx``; it needs --data for calibration frames.
``--out`` is required and an existing file (fp32, int8 or ViewNet) is replaced only with ``--force``: an
export never overwrites a model it was not told to (the shipped models/velocitynet.onnx among them).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vtr.models import int8_path
from vtr.runtime.cliargs import add_config_arguments, config_from_args, opt
from vtr.runtime.contracts import CONTROL_DT
from vtr.runtime.model_meta import CameraRange


@dataclass
class ExportConfig:
    """What `vtr export` writes."""

    checkpoint: str = opt(help="VelocityNet model.pt / checkpoint.pt (or its run folder)")
    out: str = opt(help="the fp32 ONNX file (the int8 and ViewNet files go beside it)")
    data: str | None = opt(None, "dataset: real-frame parity check and int8 calibration")
    int8: bool = opt(False, "also write <out stem>-int8.onnx (needs --data)")
    opset: int = opt(17, "ONNX opset (>= 16 so ViewNet's GridSample exports too)")
    calibration_pairs: int = 128  # (current, subgoal) pairs used to calibrate int8
    viewnet: str | None = opt(None, "also export this ViewNet checkpoint")
    viewnet_out: str | None = opt(None, "where the ViewNet ONNX goes (default: viewnet.onnx next to --out)")
    dt: float | None = opt(None, "seconds each command lasts, for a checkpoint whose dataset records no dt")
    force: bool = opt(False, "replace output files that exist (without it they are refused)")
    camera_range: str | None = opt(
        None,
        "the robot cameras the model takes, FOV0-FOV1,H0-H1 (deg, m), where measured on held-out routes "
        "(default: the training data's range, or its one camera within 2 deg / 2 cm)",
    )

    def __post_init__(self) -> None:
        if self.opset < 13:
            raise ValueError(f"ExportConfig.opset must be >= 13, got {self.opset}")
        if self.int8 and not self.data:
            raise ValueError(
                "ExportConfig.int8 needs data (calibration frames from the dataset); pass --data"
            )
        if self.calibration_pairs < 1:
            raise ValueError(f"ExportConfig.calibration_pairs must be >= 1, got {self.calibration_pairs}")
        if self.dt is not None and not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"--dt must be a positive number of seconds, got {self.dt!r}")
        if self.camera_range is not None:
            CameraRange.parse(self.camera_range)  # checked where it enters: one line, exit 2


def model_dt(data_meta: dict[str, Any], given: float | None) -> float:
    """The dt the model's metadata records: the training dataset's; ``given`` (--dt) when the checkpoint
    records none (a dataset saved before datasets carried it), else the control step, said on stderr."""
    if "dt" in data_meta:
        dt = float(data_meta["dt"])
        if given is not None and abs(given - dt) > 1e-9:
            raise ValueError(
                f"--dt {given:g} s, but the checkpoint was trained on data recorded at dt={dt:g} s"
            )
        return dt
    if given is not None:
        return given
    print(
        f"vtr export: the checkpoint records no dataset dt; the model gets the control step dt={CONTROL_DT:g} s "
        "(pass --dt to set it)",
        file=sys.stderr,
    )
    return CONTROL_DT


def _same_path(a: Any, b: Any) -> bool:
    """Whether two dataset paths name the same file or folder (False where either is missing)."""
    if not a or not b:
        return False
    try:
        return Path(str(a)).resolve() == Path(str(b)).resolve()
    except OSError:
        return False


def run(cfg: ExportConfig, data: Any = None) -> dict[str, Any]:
    """Export; ``data``: the dataset at ``cfg.data`` already loaded (``vtr train all`` loads it once)."""
    import numpy as np
    import torch

    from vtr.export.onnx_export import export_onnx, velocitynet_meta, viewnet_props
    from vtr.export.provenance import camera_of, provenance_props
    from vtr.export.quantize import calibration_pairs, compare, quantize_int8
    from vtr.training.checkpoint import load_model
    from vtr.training.dataset import load_dataset

    kind, model, ckpt = load_model(cfg.checkpoint)
    if kind != "velocitynet":
        raise ValueError(
            f"{cfg.checkpoint} holds a {kind}; `vtr export` exports VelocityNet (use --viewnet for ViewNet)"
        )
    data_meta = ckpt.get("data_meta") or {}
    dt = model_dt(data_meta, cfg.dt)
    camera = camera_of(data_meta)
    if cfg.camera_range is not None:  # measured: it replaces the data's range, the nominal camera stays
        camera.update(CameraRange.parse(cfg.camera_range).props())
    meta = velocitynet_meta(model.cfg, dt=dt, **camera)
    real = None
    if cfg.data and data is None:
        data = load_dataset(cfg.data, image_size=model.cfg.image_size)
    if data is not None:
        real = calibration_pairs(
            data.images, data.episodes, count=cfg.calibration_pairs, seed=1, preprocessing=meta.preprocessing
        )
    parity_inputs = [real[0][:16], real[1][:16]] if real is not None else None
    # the frames the model was trained on: its checkpoint says (training.train); an older one only when the
    # data given for calibration is its training data (a calibration set is not what it learnt from)
    frames = data_meta.get("frames")
    if frames is None and data is not None and _same_path(cfg.data, ckpt.get("data")):
        frames = len(data)
    props = provenance_props(*_with_run_configs(cfg.checkpoint, ckpt), frames=frames)
    result: dict[str, Any] = {
        "fp32": export_onnx(
            model, cfg.out, meta, opset=cfg.opset, real_inputs=parity_inputs, extra_props=props
        )
    }
    result["fp32"]["path"] = str(cfg.out)
    if cfg.int8 and data is not None and real is not None:
        q_path = int8_path(cfg.out)
        quantize_int8(cfg.out, q_path, *real)
        held = calibration_pairs(  # not the calibration pairs
            data.images, data.episodes, count=64, seed=2, preprocessing=meta.preprocessing
        )
        result["int8"] = {"path": str(q_path), **compare(cfg.out, q_path, *held)}
    if cfg.viewnet:
        vkind, viewnet, _ = load_model(cfg.viewnet)
        if vkind != "viewnet":
            raise ValueError(f"{cfg.viewnet} holds a {vkind}, not a ViewNet")
        v_out = cfg.viewnet_out or str(Path(cfg.out).with_name("viewnet.onnx"))
        size = viewnet.cfg.image_size
        sample = (torch.rand(1, 3, size, size), torch.zeros(1, 2))
        real_v = None
        if real is not None:
            real_v = [real[0][:8], np.tile(np.array([[0.2, 0.3]], np.float32), (min(8, len(real[0])), 1))]
        result["viewnet"] = export_onnx(
            viewnet,
            v_out,
            viewnet_props(viewnet.cfg, dt=dt),  # its own metadata: a ViewNet is not a policy
            opset=max(cfg.opset, 16),
            sample_inputs=sample,
            real_inputs=real_v,
            input_names=("image", "velocity"),
            output_names=("predicted",),
            atol=1e-3,
        )
        result["viewnet"]["path"] = v_out
    return result


def _with_run_configs(path: str, ckpt: dict[str, Any]) -> tuple[dict[str, Any], Any, Any]:
    """The checkpoint with its train_config (older model.pt files keep it only in the run folder's
    checkpoint.pt), the ViewNet checkpoint its MPC loss used and the one it was fine-tuned from
    (``--init``), where they can still be read."""
    from vtr.training.checkpoint import CheckpointError, read_checkpoint

    def read(p: Path) -> dict[str, Any] | None:
        try:
            return read_checkpoint(p) if p.exists() else None  # a file or a run folder
        except (CheckpointError, OSError, ValueError):
            return None

    folder = Path(path) if Path(path).is_dir() else Path(path).parent
    if "train_config" not in ckpt and (run := read(folder / "checkpoint.pt")) is not None:
        ckpt = {**ckpt, "train_config": run.get("train_config")}
    viewnet = read(Path(ckpt["viewnet"])) if isinstance(ckpt.get("viewnet"), str) else None
    init = read(Path(ckpt["init"])) if isinstance(ckpt.get("init"), str) else None
    return ckpt, viewnet, init


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_arguments(parser, ExportConfig)


def outputs(cfg: ExportConfig) -> list[Path]:
    """The files an export writes."""
    out = Path(cfg.out)
    paths = [out] + ([int8_path(out)] if cfg.int8 else [])
    if cfg.viewnet:
        paths.append(Path(cfg.viewnet_out) if cfg.viewnet_out else out.with_name("viewnet.onnx"))
    return paths


def check_outputs(cfg: ExportConfig) -> None:
    """ValueError (one line) for an output that is a folder, or a file that exists when --force is not given."""
    for path in outputs(cfg):
        if path.is_dir():
            raise ValueError(f"{path} is a folder; name the .onnx file to write")
        if path.exists() and not cfg.force:
            raise ValueError(f"{path} exists; pass --force to replace it, or name another --out")


def run_cli(args: argparse.Namespace) -> int:
    """A bad checkpoint or dataset is a ValueError: one line, exit 2 (``runtime.commands``)."""
    cfg = config_from_args(ExportConfig, args)
    check_outputs(cfg)  # before the checkpoint is read: nothing is replaced unasked
    result = run(cfg)
    print(json.dumps(result, indent=2))
    return 0
