"""`vtr train`: the training stages, and `vtr train all`, the one reproduce command: it runs a recipe
(training/recipe.py; default training/recipes/shipped.toml, the shipped model's) from nothing: collect ->
ViewNet -> VelocityNet stages -> export ONNX fp32 + int8 -> summary. The pipeline is the application layer:
it alone joins training and export, so neither library imports the other's command line.

`all` writes everything into its run folder (``--out``, default runs/RECIPE: recipe.json, viewnet/, one folder
per VelocityNet stage, export/, summary.json) and installs the models into ``--models-dir`` only when asked
(``--install-models``): a test run must never replace the shipped model. Rerunning the same command resumes:
finished stages (their model.pt) are skipped, an interrupted one continues from its checkpoint.pt, a collection
keeps the houses it finished; a run folder of another recipe is refused. The dataset is loaded once for every
stage and the export. After each stage its held-out result must beat its baseline (training/report.py
``check_gain``); otherwise `all` stops there with one line and exit 1, unless ``--allow-no-gain``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vtr.runtime.atomic import atomic_path, write_text_atomic
from vtr.runtime.cliargs import add_config_arguments, opt
from vtr.runtime.commands import EXIT_FAILED, EXIT_USAGE, Command, run_command
from vtr.training import cli as stages
from vtr.training.recipe import DEFAULT, Recipe, Stage, apply_overrides, claim_run_folder

# The ONNX models the runtime uses, and both torch checkpoints: ViewNet for the MPC loss and VelocityNet
# so that a user can fine-tune the shipped policy (`vtr train velocitynet --init models/velocitynet.pt`).
EXPORTED = ("velocitynet.onnx", "velocitynet-int8.onnx", "viewnet.pt", "velocitynet.pt")
TIMINGS = "timings.json"  # seconds per stage, over every invocation of the run


@dataclass
class AllConfig:
    """`vtr train all`."""

    recipe: str = opt(
        DEFAULT, "recipe: NAME (training/recipes/NAME.toml) or a .toml file", metavar="NAME|FILE"
    )
    out: str = "runs/shipped"  # run folder
    data: str | None = opt(None, "dataset (default: the recipe's); recorded first if missing or incomplete")
    models_dir: str = opt("models", "where --install-models puts the ONNX models and both torch checkpoints")
    install_models: bool = opt(False, "copy the exported models into --models-dir (replacing what is there)")
    dry_run: bool = opt(False, "print the stages, what is done and what would run; run nothing")
    allow_no_gain: bool = False  # go on past a stage that does not beat its baseline (training/report.py)


class StageStopped(RuntimeError):
    """A stage did not beat its baseline (the one-line reason): `all` stops there, exit 1."""


def _stage_check(stage_dir: Path, cfg: AllConfig) -> None:
    """Every rank reads the stage's report.json (written by rank 0 before the stage's last barrier)."""
    if stages.gain_verdict(stage_dir, cfg.allow_no_gain, "vtr train all") != 0:
        raise StageStopped(f"stopped after {stage_dir.name}")


def _houses_config(recipe: Recipe, preset: Any) -> Any:
    from vtr.training.collect_houses import HousesConfig
    from vtr.training.config import override

    c = recipe.collect
    collect = override(
        preset.collect,
        out=recipe.data,
        seed=c.get("seed"),
        noise=c.get("noise"),
        mix="repeat",
        progress=False,
        appearances=c.get("appearances"),
    )
    collect = override(collect, reverse_fraction=0.2)  # as `vtr collect --houses`
    return HousesConfig(
        out=recipe.data,
        seeds=tuple(range(int(c["houses"]))),
        frames_per_house=int(c.get("frames_per_house", 2000)),
        workers=int(c.get("workers", 0)),
        collect=collect,
        named=tuple(c.get("include_house", ())),
        named_frames=int(c.get("include_house_frames", 0)),
    )


def collect_status(recipe: Recipe, preset: Any) -> tuple[bool, str]:
    """(whether the dataset is complete, what there is) for the recipe's collect stage."""
    if not recipe.houses:
        done, frames = Path(recipe.data).exists(), recipe.collect.get("frames", preset.collect.frames)
        return done, f"{recipe.data} exists" if done else f"{frames:,} frames into {recipe.data}"
    from vtr.training.collect_houses import houses_meta, recorded_houses

    hcfg = _houses_config(recipe, preset)
    tasks, done = hcfg.tasks(), recorded_houses(hcfg, houses_meta(hcfg))
    frames = sum(n for _, _, n in tasks)
    if len(done) == len(tasks):
        return True, f"{recipe.data} holds its {len(tasks)} houses"
    return False, f"{frames:,} frames in {len(tasks)} houses into {recipe.data} ({len(done)} recorded)"


def collect(recipe: Recipe, preset: Any) -> None:
    if int(os.environ.get("WORLD_SIZE", "1")) > 1:
        raise FileNotFoundError(f"{recipe.data} is not complete; collect it before launching with torchrun")
    if recipe.houses:
        from vtr.training.collect_houses import run_houses

        run_houses(_houses_config(recipe, preset), progress=True, resume=True)
    else:
        from vtr.training.collect import run as collect_one
        from vtr.training.config import override

        c = recipe.collect
        collect_one(
            override(
                preset.collect,
                out=recipe.data,
                frames=c.get("frames"),
                seed=c.get("seed"),
                noise=c.get("noise"),
            )
        )


def _train_cfg(base: Any, stage: Stage, args: argparse.Namespace) -> Any:
    from vtr.training.config import override

    o = stage.options
    cfg = override(
        base,
        steps=o.get("steps"),
        lr=None if o.get("lr") is None else float(o["lr"]),
        batch_size=o.get("batch_size"),
        seed=o.get("seed"),
        num_threads=o.get("threads"),
        val_every=o.get("val_every"),
        augment=o.get("augment"),
        appearance_swap=None if o.get("appearance_swap") is None else float(o["appearance_swap"]),
    )
    # how to run, not what to train: from the command line only
    return override(
        cfg,
        device=args.device,
        num_workers=args.workers,
        amp=args.amp,
        data_on_device=args.data_on_device,
        max_minutes=args.max_minutes,
    )


def _velocitynet(
    out: Path, recipe: Recipe, stage: Stage, preset: Any, args: argparse.Namespace, data: Any
) -> None:
    from types import SimpleNamespace

    from vtr.training.checkpoint import MODEL
    from vtr.training.config import override
    from vtr.training.train import train_velocitynet
    from vtr.training.transfer import inherit_init_settings

    o = stage.options
    init = out / stage.init / MODEL if stage.init else None
    inherit = SimpleNamespace(init=init, preprocessing=o.get("preprocessing"), augment=o.get("augment"))
    if init is not None:
        inherit_init_settings(inherit)  # a fine-tune keeps its base's input normalisation and augmentation
    loss = override(
        preset.loss,
        w1=o.get("w1"),
        w2=o.get("w2"),
        w_consistency=None if o.get("w_consistency") is None else float(o["w_consistency"]),
    )
    model_cfg = override(preset.velocitynet, preprocessing=inherit.preprocessing)
    train = override(_train_cfg(preset.train_velocitynet, stage, args), augment=inherit.augment)
    sdir = out / stage.name
    resume = (sdir / "checkpoint.pt").exists()
    train_velocitynet(recipe.data, out / "viewnet" / MODEL, sdir, model_cfg, loss, train, resume, data, init)


def _say(i: int, n: int, stage: str, what: str, file: Any = None) -> None:
    print(f"vtr train all [{i}/{n}] {stage}: {what}", file=file or sys.stderr, flush=True)


def run_all(cfg: AllConfig, recipe: Recipe, args: argparse.Namespace) -> dict[str, Any]:
    """Run every stage of ``recipe`` not finished in ``cfg.out``; returns the summary (or the plan, dry run)."""
    from vtr.training.checkpoint import MODEL
    from vtr.training.config import get_preset

    out, preset = Path(cfg.out), get_preset(recipe.preset)
    names = ["collect", "viewnet", *(s.name for s in recipe.velocitynet), "export"]
    n = len(names)
    plan: list[tuple[str, bool, str]] = [("collect", *collect_status(recipe, preset))]
    for stage in [recipe.viewnet, *recipe.velocitynet]:
        sdir = out / stage.name
        steps = _train_cfg(
            preset.train_viewnet if stage is recipe.viewnet else preset.train_velocitynet, stage, args
        ).steps
        if (sdir / MODEL).exists():
            plan.append((stage.name, True, f"{sdir / MODEL} exists"))
        elif (sdir / "checkpoint.pt").exists():
            plan.append((stage.name, False, f"resume {sdir / 'checkpoint.pt'} to {steps} steps"))
        else:
            start = f" from {stage.init}" if stage.init else ""
            plan.append((stage.name, False, f"train {steps} steps{start} into {sdir}"))
    plan.append(("export", False, f"ONNX fp32{' + int8' if recipe.int8 else ''} into {out / 'export'}"))
    if cfg.dry_run:
        for i, (name, done, what) in enumerate(plan, 1):
            _say(i, n, name, f"done ({what})" if done else f"to run: {what}", sys.stdout)
        return {"plan": [{"stage": s, "done": d, "what": w} for s, d, w in plan]}
    claim_run_folder(out, recipe)
    # each stage's seconds, kept in the run folder: a resumed run reports the time of every stage
    tpath = out / TIMINGS
    timings: dict[str, float] = json.loads(tpath.read_text()) if tpath.exists() else {}

    def took(key: str, since: float, add: bool = True) -> None:
        timings[key] = (timings.get(key, 0.0) if add else 0.0) + time.perf_counter() - since
        if int(os.environ.get("RANK", "0")) == 0:
            write_text_atomic(tpath, json.dumps(timings, indent=1))

    data = None
    for i, (name, done, what) in enumerate(plan, 1):
        _say(i, n, name, f"done, skipped ({what})" if done else what)
        t = time.perf_counter()
        if name == "collect":
            if not done:
                collect(recipe, preset)
                took("collect_s", t)
            from vtr.training.dataset import load_dataset

            data = load_dataset(recipe.data, image_size=preset.viewnet.image_size)  # once, for every stage
        elif name == "viewnet":
            if not done:
                from vtr.training.train import train_viewnet

                vcfg = _train_cfg(preset.train_viewnet, recipe.viewnet, args)
                resume = (out / name / "checkpoint.pt").exists()
                try:
                    train_viewnet(recipe.data, out / name, preset.viewnet, vcfg, resume=resume, data=data)
                finally:
                    took("viewnet_s", t)
            _stage_check(out / name, cfg)
        elif name != "export":
            stage = next(s for s in recipe.velocitynet if s.name == name)
            if not done:
                try:
                    _velocitynet(out, recipe, stage, preset, args, data)
                finally:
                    took(f"{name}_s", t)
            _stage_check(out / name, cfg)
    if int(os.environ.get("RANK", "0")) != 0:
        return timings
    t = time.perf_counter()
    summary = export(out, recipe, cfg, data)
    took("export_s", t)
    timings["total_s"] = sum(v for k, v in timings.items() if k != "total_s")
    summary = {
        "recipe": recipe.name,
        "preset": recipe.preset,
        "data": recipe.data,
        "timings": timings,
        **summary,
    }
    for name in names[1:-1]:
        path = out / name / "report.json"
        summary.setdefault("stages", {})[name] = json.loads(path.read_text()) if path.exists() else None
    summary["viewnet"] = summary["stages"]["viewnet"]
    summary["velocitynet"] = summary["stages"][recipe.velocitynet[-1].name]  # the exported one
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=2))
    print(json.dumps({"timings": {k: round(v, 1) for k, v in timings.items()}}, indent=2))
    installed = summary["installed"]
    edir = out / "export"
    where = (
        f"installed into {cfg.models_dir}" if installed else f"in {edir} (add --install-models to use them)"
    )
    print(f"vtr train all: models {where}; figures in {out / 'summary.json'}")
    return summary


def export(out: Path, recipe: Recipe, cfg: AllConfig, data: Any) -> dict[str, Any]:
    """Export the last VelocityNet stage (fp32 + int8), copy both torch checkpoints beside, install if asked."""
    from vtr.export.cli import ExportConfig
    from vtr.export.cli import run as export_onnx
    from vtr.training.checkpoint import MODEL

    edir, last = out / "export", out / recipe.velocitynet[-1].name / MODEL
    export_cfg = ExportConfig(
        checkpoint=str(last), out=str(edir / EXPORTED[0]), data=recipe.data, int8=recipe.int8
    )
    report = export_onnx(export_cfg, data=data)
    for src, name in ((out / "viewnet" / MODEL, EXPORTED[2]), (last, EXPORTED[3])):
        with atomic_path(edir / name) as tmp:
            shutil.copyfile(src, tmp)
    installed = install(edir, Path(cfg.models_dir)) if cfg.install_models else []
    return {"export": report, "installed": installed}


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
    p.add_argument("--velocitynet-steps", type=int, help="override every VelocityNet stage's steps")
    p.add_argument("--frames", type=int, help="override the frames to collect (a houses recipe: per house)")
    p.add_argument("--no-int8", action="store_true", help="skip the int8 export")
    stages.add_common_arguments(p, pipeline=True)


#: Said when the shipped recipe is to run without a GPU: its floors stage (batch 64) is most of its time there.
CPU_HINT = (
    "vtr train all: training on the CPU: `--recipe cpu` is this recipe sized for one, its floors stage at "
    "batch 32 (50 min from nothing on 2 cores; training/README.md)"
)


def _on_cpu(device: str | None) -> bool:
    """Whether the stages will train on the CPU (``--device`` as the stages resolve it)."""
    from vtr.training.distributed import resolve_device

    try:
        return resolve_device(device or "auto").type == "cpu"
    except RuntimeError:  # CUDA asked for and missing: the first stage says so
        return False


def run_all_cli(args: argparse.Namespace) -> int:
    from vtr.training import recipe as recipes

    try:
        recipe = apply_overrides(recipes.load(args.recipe), args)
        cfg = AllConfig(
            recipe=args.recipe,
            out=args.out or f"runs/{recipe.name}",
            data=recipe.data,
            models_dir=args.models_dir,
            install_models=args.install_models,
            dry_run=args.dry_run,
            allow_no_gain=args.allow_no_gain,
        )
        if recipe.name == recipes.DEFAULT and _on_cpu(args.device):
            print(CPU_HINT, file=sys.stderr)
        run_all(cfg, recipe, args)
    except StageStopped:  # the stage check printed its line
        return EXIT_FAILED
    except ValueError as err:  # a bad recipe, another run's folder, a dataset of other settings
        print(f"vtr train all: {err}", file=sys.stderr)
        return EXIT_USAGE
    return 0


#: `vtr train STAGE`: the training stages, and `all`
COMMANDS = {
    **stages.COMMANDS,
    "all": Command(
        __name__,
        "run a recipe (default: the shipped model's): collect, ViewNet, VelocityNet stages, export fp32 + int8",
        "train",
        "add_all_arguments",
        "run_all_cli",
    ),
}

if __name__ == "__main__":  # torchrun -m vtr.pipeline all ...: the whole pipeline under DDP
    command = Command("vtr.pipeline", "train ViewNet, VelocityNet, or all", "train", subcommands=True)
    sys.exit(run_command("python -m vtr.pipeline", command, sys.argv[1:]))
