"""Training across houses and fine-tuning: held-out houses, starting weights, offline evaluation.

* ``split_for(data, cfg)``: the train/val episode split used by training. A dataset with frames from
  two or more houses (a sharded dataset from ``vtr collect --houses``) holds out whole houses, about
  ``val_fraction`` of them and at least one, so validation and the offline report are on houses that
  training never saw; a one-house dataset holds out whole episodes as before.
* ``init_weights(model, kind, model_cfg, path)``: start from given weights (``--init``): a model.pt or
  checkpoint.pt written by ``vtr train``, or the shipped ``models/viewnet.pt``. The architecture must
  match (same preset); the optimiser starts fresh. A ViewNet fine-tune keeps its base's velocity gain.
* ``vtr train evaluate --data D --viewnet V [--velocitynet P]``: the offline report of given models on
  every episode of a dataset (for example one collected in a held-out house, before and after a
  fine-tune), each figure against its baseline as in training/report.py.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from vtr.training.dataset import FrameData, split_episodes


def house_ids(data: FrameData) -> np.ndarray | None:
    """Per-frame house ids, or None for a dataset recorded in one house."""
    houses = getattr(data, "houses", None)
    if houses is None or len(np.unique(houses)) < 2:
        return None
    return np.asarray(houses)


def split_by_house(
    data: FrameData, val_fraction: float, seed: int
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(train episode ids, val episode ids, held-out house names): whole houses held out."""
    houses = house_ids(data)
    if houses is None:
        raise ValueError("the dataset holds one house: split by episodes instead")
    names = list(getattr(data, "house_names", [str(h) for h in np.unique(houses)]))
    unique = np.unique(houses)
    # Named maps (the paper-style house, a user's building) always train: only procedural houses are held
    # out, when there are at least two of them to choose from.
    procedural = np.array([h for h in unique if names[int(h)].startswith("random:")], dtype=unique.dtype)
    pool = procedural if len(procedural) >= 2 else unique
    n_val = min(len(pool) - 1, max(1, math.ceil(val_fraction * len(pool))))
    val_houses = np.sort(np.random.default_rng([seed, 5]).permutation(pool)[:n_val])
    is_val = np.isin(houses, val_houses)
    val_ids = np.unique(data.episodes[is_val])
    train_ids = np.unique(data.episodes[~is_val])
    return train_ids, val_ids, [names[int(h)] for h in val_houses]


def split_for(data: FrameData, cfg: Any) -> tuple[np.ndarray, np.ndarray]:
    """The split training uses (see the module docstring); ``data.evaluate_all`` puts every episode in both
    halves (offline evaluation of given models, where nothing is trained)."""
    if getattr(data, "evaluate_all", False):
        ids = np.unique(data.episodes)
        return ids, ids
    if house_ids(data) is not None:
        train_ids, val_ids, held_out = split_by_house(data, cfg.val_fraction, cfg.seed)
        data.meta["held_out_houses"] = held_out
        return train_ids, val_ids
    return split_episodes(data.episodes, cfg.val_fraction, cfg.seed)


def _init_checkpoint(kind: str, path: str | os.PathLike) -> tuple[Path, dict[str, Any]]:
    """(file, contents) of an ``--init`` checkpoint; ValueError/FileNotFoundError (one line) otherwise."""
    from vtr.training.checkpoint import CheckpointError, read_checkpoint

    p = Path(path)
    if p.is_dir():
        p = p / "model.pt"
    if not p.is_file():
        hint = (
            " (the shipped VelocityNet is ONNX only: pass a model.pt from `vtr train velocitynet --out DIR`)"
        )
        raise FileNotFoundError(f"--init: no checkpoint at {p}{hint if kind == 'velocitynet' else ''}")
    if p.suffix == ".onnx":
        raise ValueError(f"--init: {p} is an ONNX export (batch norm folded in); pass a .pt checkpoint")
    try:  # the one checkpoint reader: weights_only=True, so a crafted file cannot run code
        ckpt = read_checkpoint(p)
    except CheckpointError as err:
        raise ValueError(f"--init: {err}") from None
    if ckpt.get("kind") != kind:
        raise ValueError(f"--init: {p} holds a {ckpt.get('kind')!r}, not a {kind}")
    return p, ckpt


def init_weights(model: Any, kind: str, model_cfg: Any, path: str | os.PathLike) -> dict[str, Any]:
    """Load the weights of checkpoint `path` into `model` (in place); returns a note for the metadata.

    Raises ValueError (one line) when the file is not a `kind` checkpoint of the same architecture."""
    from vtr.training.config import to_dict, viewnet_config

    p, ckpt = _init_checkpoint(kind, path)
    theirs, ours = ckpt.get("model_config") or {}, to_dict(model_cfg)
    if kind == "viewnet" and theirs:
        theirs = to_dict(viewnet_config(theirs))  # an older checkpoint records no velocity gain
    if theirs != ours:
        differ = ", ".join(
            f"{k} {theirs.get(k)!r} (here {ours.get(k)!r})" for k in ours if theirs.get(k) != ours[k]
        )
        raise ValueError(
            f"--init: {p} differs from this preset's {kind} in {differ}; train with the base's settings"
        )
    model.load_state_dict(ckpt["state_dict"])
    return {"init": str(p), "init_step": ckpt.get("step"), "init_data": ckpt.get("data")}


def init_viewnet_config(model_cfg: Any, path: str | os.PathLike) -> Any:
    """A ViewNet fine-tune keeps its base's velocity gain: the base's weights were learned with it (the
    shipped models/viewnet.pt predates the gain and keeps 1)."""
    from vtr.training.config import override, viewnet_config

    _, ckpt = _init_checkpoint("viewnet", path)
    base = viewnet_config(ckpt.get("model_config") or {})
    return override(model_cfg, velocity_gain=base.velocity_gain)


def inherit_init_settings(args: argparse.Namespace) -> None:
    """Fine-tuning a VelocityNet keeps its input normalisation and augmentation: `--preprocessing` and
    `--augment` left unset take the values the `--init` checkpoint was trained with (a preprocessing that
    differs from the base's would silently feed the network inputs it never saw)."""
    from vtr.training.checkpoint import CheckpointError, read_checkpoint

    p = Path(args.init)
    p = p / "model.pt" if p.is_dir() else p
    if not p.is_file() or p.suffix == ".onnx":
        return  # init_weights gives the one-line error
    try:
        ckpt = read_checkpoint(p)
    except CheckpointError:
        return
    if args.preprocessing is None:
        args.preprocessing = (ckpt.get("model_config") or {}).get("preprocessing")
    if args.augment is None and isinstance(ckpt.get("augment"), bool):
        args.augment = ckpt["augment"]


# --------------------------------------------------------------------------------------------- evaluate
def evaluate(
    data_path: str, viewnet_path: str, velocitynet_path: str | None, preset: str = "default", batch: int = 32
) -> dict[str, Any]:
    """Offline report of given models on every episode of `data_path` (nothing is trained)."""
    import torch

    from vtr.training.checkpoint import load_model
    from vtr.training.config import get_preset
    from vtr.training.dataset import load_dataset
    from vtr.training.distributed import setup_dist
    from vtr.training.report import velocitynet_report, viewnet_report
    from vtr.training.windows import Windows

    cfgs = get_preset(preset)
    dist = setup_dist(cfgs.train_viewnet)
    kind, viewnet, _ = load_model(viewnet_path)
    if kind != "viewnet":
        raise ValueError(f"{viewnet_path} holds a {kind}, not a ViewNet")
    data = load_dataset(data_path, image_size=viewnet.cfg.image_size)
    data.evaluate_all = True  # type: ignore[attr-defined]
    out: dict[str, Any] = {"data": str(data_path), "frames": len(data), "houses": data.meta.get("houses")}
    out["viewnet"] = viewnet_report(viewnet, Windows(data, 2, cfgs.train_viewnet, dist), batch)
    if velocitynet_path is not None:
        kind, velocitynet, ckpt = load_model(velocitynet_path)
        if kind != "velocitynet":
            raise ValueError(f"{velocitynet_path} holds a {kind}, not a VelocityNet")
        loss_cfg = cfgs.loss
        if "loss_config" in ckpt:
            from vtr.training.config import MPCLossConfig, from_dict

            loss_cfg = from_dict(MPCLossConfig, ckpt["loss_config"])
        windows = Windows(data, loss_cfg.horizon + 1, cfgs.train_velocitynet, dist)
        if "mean_command" in ckpt:  # the baseline is the mean command of the model's own training data
            windows.mean_command = np.asarray(ckpt["mean_command"], dtype=np.float32)
        with torch.no_grad():
            out["velocitynet"] = velocitynet_report(velocitynet, viewnet, windows, loss_cfg, batch)
    return out


def add_evaluate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True, help="dataset (.npz or a sharded folder); every episode is used")
    p.add_argument(
        "--viewnet", required=True, help="ViewNet checkpoint (model.pt, its folder, models/viewnet.pt)"
    )
    p.add_argument("--velocitynet", default=None, help="VelocityNet checkpoint (model.pt or its folder)")
    p.add_argument("--preset", default="default", help="preset whose loss settings apply (default: default)")
    p.add_argument("--json", dest="json_path", default=None, help="also write the report here (atomically)")


def run_evaluate(args: argparse.Namespace) -> int:
    from vtr.runtime.atomic import write_text_atomic
    from vtr.training.dataset import DatasetError
    from vtr.training.report import format_report

    try:
        report = evaluate(args.data, args.viewnet, args.velocitynet, args.preset)
    except (DatasetError, FileNotFoundError, ValueError) as err:
        print(f"vtr train evaluate: {err}", file=sys.stderr)
        return 1
    print(format_report(report["viewnet"]))
    if "velocitynet" in report:
        print(format_report(report["velocitynet"]))
    if args.json_path:
        write_text_atomic(args.json_path, json.dumps(report, indent=2) + "\n")
    return 0
