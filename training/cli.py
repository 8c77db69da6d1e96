"""The training stages' command line: `vtr train viewnet|velocitynet` (the `all` pipeline, which also
collects and exports, is the application layer's: ``vtr/pipeline.py``).

    vtr train viewnet --data data/house.npz --out runs/default/viewnet [--preset default]
    vtr train velocitynet --data data/house.npz --viewnet runs/default/viewnet/model.pt --out runs/default/velocitynet
    vtr train velocitynet --init runs/default/velocitynet/model.pt --data my_building.npz ...   # fine-tune
    vtr train evaluate --data data/heldout --viewnet models/viewnet.pt --velocitynet runs/x/velocitynet

Every stage resumes from its checkpoint with --resume. Under torchrun the same stages train with
DistributedDataParallel (gloo on CPU, nccl on CUDA): ``torchrun --nproc_per_node=K -m vtr.training.app viewnet ...``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from vtr.runtime.commands import EXIT_FAILED, Command
from vtr.runtime.preprocess import PREPROCESSINGS
from vtr.training.config import MAX_RATIO


def _add_common(p: argparse.ArgumentParser, pipeline: bool = False) -> None:
    if pipeline:  # `vtr train all`: the recipe gives both
        p.add_argument("--preset", default=None, help="tiny | default | paper (default: the recipe's)")
        p.add_argument("--out", default=None, help="run folder (default: runs/RECIPE)")
    else:
        p.add_argument("--preset", default="default", help="tiny | default | paper (default: default)")
        p.add_argument("--out", required=True, help="output folder (checkpoints, metrics.jsonl, report.json)")
    resume = (
        "kept for old scripts: a rerun always resumes"
        if pipeline
        else "continue from the checkpoint in --out"
    )
    p.add_argument("--resume", action="store_true", help=resume)
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
        "--max-minutes",
        type=float,
        help="stop after this much wall time, validate and save as if done (default 0: no limit)",
    )
    p.add_argument(
        "--augment",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="photometric augmentation of VelocityNet's inputs (training/augment.py; default: off)",
    )
    p.add_argument(
        "--appearance-swap",
        type=float,
        default=None,
        metavar="P",
        help="velocitynet: share of windows whose subgoal or current side comes from the same poses in another "
        "appearance (a dataset collected with --appearances; training/appearances.py; default 0)",
    )
    p.add_argument(
        "--preprocessing",
        choices=PREPROCESSINGS,
        default=None,
        help=f"VelocityNet's input normalisation, stored in the exported model (default: {PREPROCESSINGS[0]})",
    )
    p.add_argument(
        "--allow-no-gain",
        action="store_true",
        help=f"go on when a stage's held-out result is above {MAX_RATIO}x its baseline (ViewNet: copy-the-input, "
        "VelocityNet: the mean command); without it the stage stops with exit 1",
    )
    p.add_argument(
        "--data-on-device",
        choices=("auto", "yes", "no"),
        help="keep the whole dataset on the training device (auto: if it takes < 1/4 of free GPU memory)",
    )


def add_common_arguments(p: argparse.ArgumentParser, pipeline: bool = False) -> None:
    """The options every training stage shares (``vtr train all`` adds its own; ``pipeline``: its defaults)."""
    _add_common(p, pipeline)


def add_viewnet_arguments(p: argparse.ArgumentParser) -> None:
    p.set_defaults(stage="viewnet")
    p.add_argument("--data", required=True, help="dataset from `vtr collect`")
    p.add_argument("--init", default=None, help="start from this ViewNet checkpoint (e.g. models/viewnet.pt)")
    _add_common(p)


def add_velocitynet_arguments(p: argparse.ArgumentParser) -> None:
    p.set_defaults(stage="velocitynet")
    p.add_argument("--data", required=True, help="dataset from `vtr collect`")
    p.add_argument("--viewnet", required=True, help="trained ViewNet (model.pt or its folder)")
    p.add_argument(
        "--init", default=None, help="start from this VelocityNet checkpoint (model.pt) to fine-tune"
    )
    p.add_argument(
        "--recovery",
        default=None,
        metavar="DIR",
        help="recovery views of --data (`vtr collect --recovery-for`): off-path views with corrective labels",
    )
    p.add_argument(
        "--w-recovery",
        type=float,
        default=None,
        help="weight of the recovery term (default: 0, or 0.5 when --recovery is given)",
    )
    p.add_argument(
        "--w-stop",
        type=float,
        default=None,
        help="weight of the stop term, VelocityNet(I, I) -> 0: stand still on the subgoal (default: 0)",
    )
    p.add_argument(
        "--w-consistency",
        type=float,
        default=None,
        help="weight of the floor-consistency term: the command must not change when the current image's floor "
        "is laid again (an --appearances dataset; training/consistency.py; default: 0)",
    )
    _add_common(p)


#: The stages (`vtr train STAGE`, and `python -m vtr.training.app STAGE` for torchrun).
COMMANDS = {
    "viewnet": Command(
        __name__,
        "train ViewNet (next-frame prediction, L1, forward + reversed pairs)",
        "train",
        "add_viewnet_arguments",
    ),
    "velocitynet": Command(
        __name__,
        "train VelocityNet with the offline MPC loss (ViewNet frozen)",
        "train",
        "add_velocitynet_arguments",
    ),
    "evaluate": Command(
        "vtr.training.transfer",
        "offline report of given models on a dataset",
        "train",
        "add_evaluate_arguments",
        "run_evaluate",
    ),
}


def train_cfg(base: Any, args: argparse.Namespace, steps: int | None = None) -> Any:
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
        augment=getattr(args, "augment", None),
        appearance_swap=getattr(args, "appearance_swap", None),
        max_minutes=getattr(args, "max_minutes", None),
    )


def run_cli(args: argparse.Namespace) -> int:
    """Run the ``viewnet`` or ``velocitynet`` stage (``args.stage``); a bad dataset or checkpoint is one line, exit 2."""
    from vtr.training.config import get_preset, override
    from vtr.training.train import train_velocitynet, train_viewnet

    if args.stage == "velocitynet" and args.init:
        from vtr.training.transfer import inherit_init_settings

        inherit_init_settings(args)  # a fine-tune keeps the base's preprocessing and augmentation
    preset = get_preset(args.preset)
    w_rec = getattr(args, "w_recovery", None)
    if w_rec is None and getattr(args, "recovery", None):
        w_rec = 0.5
    preset.loss = override(
        preset.loss,
        w1=args.w1,
        w2=args.w2,
        w_recovery=w_rec,
        w_stop=getattr(args, "w_stop", None),
        w_consistency=getattr(args, "w_consistency", None),
    )
    preset.velocitynet = override(preset.velocitynet, preprocessing=args.preprocessing)
    if args.stage == "viewnet":
        report = train_viewnet(
            args.data,
            args.out,
            preset.viewnet,
            train_cfg(preset.train_viewnet, args),
            args.resume,
            init=args.init,
        )
    else:
        report = train_velocitynet(
            args.data,
            args.viewnet,
            args.out,
            preset.velocitynet,
            preset.loss,
            train_cfg(preset.train_velocitynet, args),
            args.resume,
            init=args.init,
            recovery=args.recovery,
        )
    if not report:  # under torchrun only rank 0 writes the report, and checks it
        return 0
    return gain_verdict(args.out, args.allow_no_gain, f"vtr train {args.stage}")


def gain_verdict(out: str | Path, allow: bool, where: str) -> int:
    """The stage check: 0 when the stage in ``out`` learned (its report.json against its baseline) or
    ``allow``; otherwise one line on stderr and EXIT_FAILED."""
    import json

    from vtr.training.checkpoint import REPORT
    from vtr.training.report import NoGainError, check_gain

    try:
        check_gain(json.loads((Path(out) / REPORT).read_text()), str(out))
    except NoGainError as err:
        if allow:
            print(f"{where}: going on (--allow-no-gain): {err}", file=sys.stderr)
            return 0
        print(f"{where}: {err}", file=sys.stderr)
        return EXIT_FAILED
    return 0
