"""Checkpoint files: written atomically, read with ``torch.load(weights_only=True)``.

A checkpoint holds tensors and plain data only (str, int, float, bool, None, lists, tuples and dicts of
them): ``save_checkpoint`` refuses anything else, so every file we write loads without unpickling
arbitrary objects, and ``read_checkpoint`` refuses a file that would need it (a crafted pickle runs no
code here). Before torch reads a file, its zip directory is checked (runtime.npz_guard.check_zip): torch
allocates each member's declared size, so a 400 KB file could take 400 MB; members may total at most 4x the
file's size (``torch.save`` stores them uncompressed). Readers (export, evaluation, the latency benchmark)
import this module, not the training loop.
"""

from __future__ import annotations

import os
import pickle
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from vtr.runtime.atomic import atomic_path
from vtr.runtime.npz_guard import MAX_EXPANSION, NpzTooLargeError, check_zip
from vtr.training.config import VelocityNetConfig, from_dict, viewnet_config
from vtr.training.models import VelocityNet, ViewNet

CHECKPOINT = "checkpoint.pt"
MODEL = "model.pt"
METRICS = "metrics.jsonl"
REPORT = "report.json"
#: More zip members than this is not one of our checkpoints (one per tensor, optimizer state included).
MAX_MEMBERS = 100_000


class CheckpointError(ValueError):
    """A file that is not a checkpoint we can read safely; the message names the file and the fix."""


def plain(obj: Any) -> Any:
    """``obj`` with numpy scalars and arrays turned into Python numbers and lists (tensors kept)."""
    if isinstance(obj, np.generic):  # before float: np.float64 is a float subclass torch will not load
        return obj.item()
    if isinstance(obj, torch.Tensor | str | int | float | bool) or obj is None:
        return obj
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Mapping):
        return {k: plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return type(obj)(plain(v) for v in obj)
    raise TypeError(f"a checkpoint holds tensors and plain data only, not {type(obj).__name__}")


def save_checkpoint(obj: Mapping[str, Any], path: str | os.PathLike[str]) -> None:
    """Write ``obj`` (made plain first) to ``path`` atomically."""
    data = plain(dict(obj))
    with atomic_path(Path(path)) as tmp:
        torch.save(data, tmp)


def read_checkpoint(path: str | os.PathLike[str], map_location: str | torch.device = "cpu") -> dict[str, Any]:
    """The checkpoint's contents; CheckpointError for a missing, garbage or unsafe file."""
    path = Path(path)
    if path.is_dir():
        if not (path / MODEL).is_file():
            raise IsADirectoryError(
                f"{path} is a folder without a {MODEL}, not a model checkpoint; pass the checkpoint file or a "
                "`vtr train` run folder"
            )
        path = path / MODEL
    if not path.is_file():
        raise FileNotFoundError(f"no model checkpoint at {path}")
    if not zipfile.is_zipfile(path):
        raise CheckpointError(
            f"{path} is not a torch checkpoint (not the zip archive torch.save writes); pass a model.pt "
            "written by `vtr train`"
        )
    try:
        check_zip(path, MAX_EXPANSION, MAX_MEMBERS, what="a torch checkpoint")
    except NpzTooLargeError as exc:
        raise CheckpointError(f"{exc}; pass a model.pt written by `vtr train`") from None
    try:
        data = torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as exc:
        why = [line.strip() for line in str(exc).splitlines() if "Unsupported global" in line]
        if not why:
            raise CheckpointError(
                f"{path} is not a torch checkpoint (it does not unpickle); pass a model.pt written by `vtr train`"
            ) from None
        reason = why[0].removeprefix("WeightsUnpickler error: ").split(" was not")[0][:140]
        raise CheckpointError(
            f"{path} needs more than tensors and plain data to load ({reason}); "
            "refusing it: only checkpoints written by `vtr train` are read"
        ) from None
    except (RuntimeError, EOFError, OSError, ValueError) as exc:
        raise CheckpointError(
            f"{path} is not a torch checkpoint ({type(exc).__name__}); pass a model.pt written by `vtr train`"
        ) from None
    if not isinstance(data, dict):
        raise CheckpointError(f"{path} is not a vtr checkpoint (it holds a {type(data).__name__})")
    return data


def load_model(
    path: str | os.PathLike[str], map_location: str | torch.device = "cpu"
) -> tuple[str, nn.Module, dict[str, Any]]:
    """(kind, model in eval mode, the whole file) from a model.pt or checkpoint.pt (or its folder)."""
    ckpt = read_checkpoint(path, map_location)
    kind = ckpt.get("kind")
    try:
        if kind == "viewnet":
            model: nn.Module = ViewNet(viewnet_config(ckpt["model_config"]))
        elif kind == "velocitynet":
            model = VelocityNet(from_dict(VelocityNetConfig, ckpt["model_config"]))
        else:
            raise CheckpointError(f"{path} is not a vtr model checkpoint (kind={kind!r})")
        model.load_state_dict(ckpt["state_dict"])
    except (KeyError, TypeError, RuntimeError) as exc:
        raise CheckpointError(
            f"{path}: a {kind} checkpoint that does not fit its model ({str(exc)[:160]})"
        ) from None
    return kind, model.eval(), ckpt
