"""`vtr train viewnet|velocitynet|all`: the training command line.

    vtr train viewnet --data data/house.npz --out runs/default/viewnet [--preset default]
    vtr train velocitynet --data data/house.npz --viewnet runs/default/viewnet/model.pt --out runs/default/velocitynet
    vtr train all --preset default --out runs/default   # collect (if needed), both nets, export to models/
    vtr train velocitynet --init runs/default/velocitynet/model.pt --data my_building.npz ...   # fine-tune
    vtr train evaluate --data data/heldout --viewnet models/viewnet.pt --velocitynet runs/x/velocitynet

Every stage resumes from its checkpoint with --resume. Under `torchrun --nproc_per_node=K` the same
commands train with DistributedDataParallel (gloo on CPU, nccl on CUDA).
"""

from __future__ import annotations

import argparse
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vtr.runtime.atomic import atomic_path, write_text_atomic


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", default="default", help="tiny | default | paper (default: default)")
    p.add_argument("--out", required=True, help="output folder (checkpoints, metrics.jsonl, report.json)")
    p.add_argument("--resume", action="store_true", help="continue from the checkpoint in --out")
    p.add_argument("--steps", type=int, help="override the preset's number of optimiser steps")
    p.add_argument("--batch-size", type=int, help="override the preset's batch size (per process)")
    p.add_argument("--lr", type=float, help="override the learning rate (paper: 1e-4; default preset: 1e-3)")
    p.add_argument("--w1", type=float, help="override the MPC loss image weight (paper: 0.8)")
    p.add_argument(
        "--w2", type=float, help="override the MPC loss velocity weight (paper: 0.3; 0 for the ablation)"
    )
    p.add_argument("--seed", type=int, help="override the seed")
    p.add_argument("--device", help="auto | cpu | cuda | cuda:K (default: auto)")
    p.add_argument("--threads", type=int, help="torch CPU threads (0: torch's default)")
    p.add_argument("--workers", type=int, help="DataLoader workers when the data is not on the device")
    p.add_argument(
        "--amp", action=argparse.BooleanOptionalAction, default=None, help="bfloat16 autocast on CUDA"
    )
    p.add_argument("--val-every", type=int, help="steps between validation passes and checkpoints")
    p.add_argument(
        "--data-on-device",
        choices=("auto", "yes", "no"),
        help="keep the whole dataset on the training device (auto: if it takes < 1/4 of free GPU memory)",
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="stage", required=True)
    p = sub.add_parser("viewnet", help="train ViewNet (next-frame prediction, L1, forward + reversed pairs)")
    p.add_argument("--data", required=True, help="dataset from `vtr collect`")
    p.add_argument("--init", default=None, help="start from this ViewNet checkpoint (e.g. models/viewnet.pt)")
    _add_common(p)
    p = sub.add_parser("velocitynet", help="train VelocityNet with the offline MPC loss (ViewNet frozen)")
    p.add_argument("--data", required=True, help="dataset from `vtr collect`")
    p.add_argument("--viewnet", required=True, help="trained ViewNet (model.pt or its folder)")
    p.add_argument(
        "--init", default=None, help="start from this VelocityNet checkpoint (model.pt) to fine-tune"
    )
    _add_common(p)
    from vtr.training.transfer import add_evaluate_arguments

    add_evaluate_arguments(sub.add_parser("evaluate", help="offline report of given models on a dataset"))
    p = sub.add_parser("all", help="collect if needed, train ViewNet, VelocityNet, export ONNX (fp32 + int8)")
    p.add_argument("--data", default="data/house.npz", help="dataset; recorded first if it does not exist")
    p.add_argument("--models-dir", default="models", help="where the ONNX models and ViewNet checkpoint go")
    p.add_argument("--viewnet-steps", type=int, help="override ViewNet's steps")
    p.add_argument("--velocitynet-steps", type=int, help="override VelocityNet's steps")
    p.add_argument("--frames", type=int, help="override the number of frames to collect")
    p.add_argument("--no-int8", action="store_true", help="skip the int8 export")
    _add_common(p)


def _train_cfg(base: Any, args: argparse.Namespace, steps: int | None = None) -> Any:
    from vtr.training.config import override

    return override(
        base,
        steps=steps if steps is not None else getattr(args, "steps", None),
        batch_size=args.batch_size,
        lr=args.lr,
        seed=args.seed,
        device=args.device,
        num_threads=args.threads,
        num_workers=args.workers,
        amp=args.amp,
        val_every=args.val_every,
        data_on_device=args.data_on_device,
    )


@dataclass
class AllConfig:
    """`vtr train all`: the one reproduce command."""

    preset: str = "default"  # preset name (training/config.py)
    out: str = "runs/default"  # run folder: viewnet/, velocitynet/, timings.json
    data: str = "data/house.npz"  # dataset; collected with the preset's CollectConfig if missing
    models_dir: str = "models"  # velocitynet.onnx, velocitynet-int8.onnx, viewnet.pt go here
    resume: bool = False  # continue interrupted stages; finished stages are always skipped
    int8: bool = True  # also write the int8 model

    def __post_init__(self) -> None:
        from vtr.training.config import PRESETS

        if self.preset not in PRESETS:
            raise ValueError(f"AllConfig.preset must be one of {sorted(PRESETS)}, got {self.preset!r}")


def run_all(cfg: AllConfig, preset: Any) -> dict[str, Any]:
    """Collect (if needed) -> ViewNet -> VelocityNet -> export. Stages already finished are skipped."""
    import json

    from vtr.training.train import MODEL, train_velocitynet, train_viewnet

    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    if not Path(cfg.data).exists():
        from vtr.training.collect import run as collect
        from vtr.training.config import override

        if int(os.environ.get("WORLD_SIZE", "1")) > 1:
            raise FileNotFoundError(f"{cfg.data} does not exist; collect it before launching with torchrun")
        collect(override(preset.collect, out=cfg.data))
        timings["collect_s"] = time.perf_counter() - t0
    vdir, pdir = out / "viewnet", out / "velocitynet"
    t = time.perf_counter()
    if not (vdir / MODEL).exists():
        train_viewnet(cfg.data, vdir, preset.viewnet, preset.train_viewnet, resume=cfg.resume)
        timings["viewnet_s"] = time.perf_counter() - t
    t = time.perf_counter()
    if not (pdir / MODEL).exists():
        train_velocitynet(
            cfg.data,
            vdir / MODEL,
            pdir,
            preset.velocitynet,
            preset.loss,
            preset.train_velocitynet,
            resume=cfg.resume,
        )
        timings["velocitynet_s"] = time.perf_counter() - t
    if int(os.environ.get("RANK", "0")) != 0:
        return timings
    t = time.perf_counter()
    from vtr.export.cli import ExportConfig
    from vtr.export.cli import run as export

    models = Path(cfg.models_dir)
    models.mkdir(parents=True, exist_ok=True)
    export_report = export(
        ExportConfig(
            checkpoint=str(pdir / MODEL), out=str(models / "velocitynet.onnx"), data=cfg.data, int8=cfg.int8
        )
    )
    with atomic_path(models / "viewnet.pt") as tmp:
        shutil.copyfile(vdir / MODEL, tmp)
    timings["export_s"] = time.perf_counter() - t
    timings["total_s"] = time.perf_counter() - t0
    summary = {"preset": cfg.preset, "timings": timings, "export": export_report}
    for name in ("viewnet", "velocitynet"):
        path = out / name / "report.json"
        summary[name] = json.loads(path.read_text()) if path.exists() else None
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=2))
    print(json.dumps({"timings": timings}, indent=2))
    return summary


def run_cli(args: argparse.Namespace) -> int:
    from vtr.training.config import get_preset, override
    from vtr.training.dataset import DatasetError
    from vtr.training.train import train_velocitynet, train_viewnet

    if args.stage == "evaluate":
        from vtr.training.transfer import run_evaluate

        return run_evaluate(args)
    preset = get_preset(args.preset)
    preset.loss = override(preset.loss, w1=args.w1, w2=args.w2)
    try:
        if args.stage == "viewnet":
            train_viewnet(
                args.data,
                args.out,
                preset.viewnet,
                _train_cfg(preset.train_viewnet, args),
                args.resume,
                init=args.init,
            )
        elif args.stage == "velocitynet":
            train_velocitynet(
                args.data,
                args.viewnet,
                args.out,
                preset.velocitynet,
                preset.loss,
                _train_cfg(preset.train_velocitynet, args),
                args.resume,
                init=args.init,
            )
        else:
            preset.train_viewnet = _train_cfg(preset.train_viewnet, args, args.viewnet_steps)
            preset.train_velocitynet = _train_cfg(preset.train_velocitynet, args, args.velocitynet_steps)
            if args.frames is not None:
                preset.collect = override(preset.collect, frames=args.frames)
            cfg = AllConfig(
                preset=args.preset,
                out=args.out,
                data=args.data,
                models_dir=args.models_dir,
                resume=args.resume,
                int8=not args.no_int8,
            )
            run_all(cfg, preset)
    except (DatasetError, FileExistsError, FileNotFoundError, ValueError) as err:
        print(f"vtr train: {err}")
        return 1
    return 0
