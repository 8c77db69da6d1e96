"""`vtr train`: the training stages, and `vtr train all`, the one reproduce command (collect if the dataset
is missing -> ViewNet -> VelocityNet -> export ONNX fp32 + int8). The pipeline is the application layer:
it alone joins training and export, so neither library imports the other's command line.

`all` writes everything into its run folder (``--out``: viewnet/, velocitynet/, export/, summary.json) and
installs the models into ``--models-dir`` only when asked (``--install-models``): a test run must never
replace the shipped model. The dataset is loaded once for both stages and the export. After each stage its
held-out result must beat its baseline (training/report.py ``check_gain``); otherwise `all` stops there with
one line and exit 1, unless ``--allow-no-gain``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vtr.runtime.atomic import atomic_path, write_text_atomic
from vtr.runtime.cliargs import add_config_arguments, opt
from vtr.runtime.commands import EXIT_FAILED, Command, run_command
from vtr.training import cli as stages

# The ONNX models the runtime uses, and both torch checkpoints: ViewNet for the MPC loss and VelocityNet
# so that a user can fine-tune the shipped policy (`vtr train velocitynet --init models/velocitynet.pt`).
EXPORTED = ("velocitynet.onnx", "velocitynet-int8.onnx", "viewnet.pt", "velocitynet.pt")


@dataclass
class AllConfig:
    """`vtr train all`."""

    preset: str = "default"  # preset name (training/config.py)
    out: str = "runs/default"  # run folder: viewnet/, velocitynet/, export/, summary.json
    data: str = opt(
        "data/house.npz", "dataset; recorded first with the preset's settings if it does not exist"
    )
    models_dir: str = opt("models", "where --install-models puts the ONNX models and both torch checkpoints")
    install_models: bool = opt(False, "copy the exported models into --models-dir (replacing what is there)")
    resume: bool = False  # continue interrupted stages; finished stages are always skipped
    int8: bool = True  # also write the int8 model
    allow_no_gain: bool = False  # go on past a stage that does not beat its baseline (training/report.py)

    def __post_init__(self) -> None:
        from vtr.training.config import PRESETS

        if self.preset not in PRESETS:
            raise ValueError(f"preset must be one of {sorted(PRESETS)}, got {self.preset!r}")


class StageStopped(RuntimeError):
    """A stage did not beat its baseline (the one-line reason): `all` stops there, exit 1."""


def _stage_check(stage_dir: Path, cfg: AllConfig) -> None:
    """Every rank reads the stage's report.json (written by rank 0 before the stage's last barrier)."""
    if stages.gain_verdict(stage_dir, cfg.allow_no_gain, "vtr train all") != 0:
        raise StageStopped(f"stopped after {stage_dir.name}")


def run_all(cfg: AllConfig, preset: Any) -> dict[str, Any]:
    """Collect (if needed) -> ViewNet -> VelocityNet -> export. Stages already finished are skipped; each
    trained stage (this run's or an earlier one's) must beat its baseline before the next one starts."""
    from vtr.export.cli import ExportConfig
    from vtr.export.cli import run as export
    from vtr.training.checkpoint import MODEL
    from vtr.training.dataset import load_dataset
    from vtr.training.train import train_velocitynet, train_viewnet

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
    data = load_dataset(cfg.data, image_size=preset.viewnet.image_size)  # once, for every stage
    vdir, pdir, edir = out / "viewnet", out / "velocitynet", out / "export"
    t = time.perf_counter()
    if not (vdir / MODEL).exists():
        train_viewnet(cfg.data, vdir, preset.viewnet, preset.train_viewnet, resume=cfg.resume, data=data)
        timings["viewnet_s"] = time.perf_counter() - t
    _stage_check(vdir, cfg)
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
            data=data,
        )
        timings["velocitynet_s"] = time.perf_counter() - t
    _stage_check(pdir, cfg)
    if int(os.environ.get("RANK", "0")) != 0:
        return timings
    t = time.perf_counter()
    export_cfg = ExportConfig(
        checkpoint=str(pdir / MODEL), out=str(edir / EXPORTED[0]), data=cfg.data, int8=cfg.int8
    )
    export_report = export(export_cfg, data=data)
    for src, name in ((vdir / MODEL, EXPORTED[2]), (pdir / MODEL, EXPORTED[3])):
        with atomic_path(edir / name) as tmp:
            shutil.copyfile(src, tmp)
    timings["export_s"] = time.perf_counter() - t
    installed = install(edir, Path(cfg.models_dir)) if cfg.install_models else []
    timings["total_s"] = time.perf_counter() - t0
    summary = {"preset": cfg.preset, "timings": timings, "export": export_report, "installed": installed}
    for name in ("viewnet", "velocitynet"):
        path = out / name / "report.json"
        summary[name] = json.loads(path.read_text()) if path.exists() else None
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=2))
    print(json.dumps({"timings": timings}, indent=2))
    where = (
        f"installed into {cfg.models_dir}" if installed else f"in {edir} (add --install-models to use them)"
    )
    print(f"vtr train all: models {where}")
    return summary


def install(export_dir: Path, models_dir: Path) -> list[str]:
    """Copy the exported models into ``models_dir`` atomically; returns the files written."""
    models_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name in EXPORTED:
        src = export_dir / name
        if src.is_file():
            with atomic_path(models_dir / name) as tmp:
                shutil.copyfile(src, tmp)
            written.append(str(models_dir / name))
    return written


def add_all_arguments(p: argparse.ArgumentParser) -> None:
    add_config_arguments(p, AllConfig)
    p.add_argument("--viewnet-steps", type=int, help="override ViewNet's steps")
    p.add_argument("--velocitynet-steps", type=int, help="override VelocityNet's steps")
    p.add_argument("--frames", type=int, help="override the number of frames to collect")
    p.add_argument("--no-int8", action="store_true", help="skip the int8 export")
    stages.add_common_arguments(p)


def run_all_cli(args: argparse.Namespace) -> int:
    from vtr.training.config import get_preset, override

    preset = get_preset(args.preset)
    preset.loss = override(preset.loss, w1=args.w1, w2=args.w2)
    preset.velocitynet = override(preset.velocitynet, preprocessing=args.preprocessing)
    preset.train_viewnet = stages.train_cfg(preset.train_viewnet, args, args.viewnet_steps)
    preset.train_velocitynet = stages.train_cfg(preset.train_velocitynet, args, args.velocitynet_steps)
    if args.frames is not None:
        preset.collect = override(preset.collect, frames=args.frames)
    cfg = AllConfig(
        preset=args.preset,
        out=args.out,
        data=args.data,
        models_dir=args.models_dir,
        install_models=args.install_models,
        resume=args.resume,
        int8=not args.no_int8,
        allow_no_gain=args.allow_no_gain,
    )
    try:
        run_all(cfg, preset)
    except StageStopped:  # the stage check printed its line
        return EXIT_FAILED
    return 0


#: `vtr train STAGE`: the training stages, and `all`
COMMANDS = {
    **stages.COMMANDS,
    "all": Command(
        __name__,
        "collect if needed, train ViewNet, VelocityNet, export ONNX (fp32 + int8)",
        "train",
        "add_all_arguments",
        "run_all_cli",
    ),
}

if __name__ == "__main__":  # torchrun -m vtr.pipeline all ...: the whole pipeline under DDP
    import sys

    command = Command("vtr.pipeline", "train ViewNet, VelocityNet, or all", "train", subcommands=True)
    sys.exit(run_command("python -m vtr.pipeline", command, sys.argv[1:]))
