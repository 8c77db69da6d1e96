"""Training loops for ViewNet and VelocityNet (offline MPC), single process or under torchrun/DDP.

Each stage writes into its output folder:
    checkpoint.pt   resumable state (model, optimiser, step), rewritten atomically every val_every steps
    model.pt        the trained model (kind, config, weights), written once at the end
    metrics.jsonl   one JSON object per log line (train and val)
    report.json     the offline quality report (training/report.py)

Batches are a pure function of (seed, step, rank), so a resumed run sees the same batches it would have.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from vtr.runtime.atomic import atomic_path, write_text_atomic
from vtr.runtime.preprocess import PREPROCESSING
from vtr.training.config import (
    MPCLossConfig,
    TrainConfig,
    VelocityNetConfig,
    ViewNetConfig,
    from_dict,
    to_dict,
)
from vtr.training.dataset import DatasetError, FrameData, load_dataset, window_starts
from vtr.training.losses import mpc_loss, viewnet_loss
from vtr.training.models import VelocityNet, ViewNet
from vtr.training.transfer import init_weights, split_for

CHECKPOINT = "checkpoint.pt"
MODEL = "model.pt"
METRICS = "metrics.jsonl"
REPORT = "report.json"
_SCALE = np.float32(1.0 / 255.0)


def images_to_float(images: torch.Tensor) -> torch.Tensor:
    """uint8 (..., H, W, 3) -> float32 (..., 3, H, W) in [0, 1]: runtime.preprocess.to_nchw in torch.

    Kept bit-identical to ``to_nchw`` (a test checks) so training and the runtime cannot drift.
    """
    assert PREPROCESSING == "rgb8_hwc_to_float32_nchw_div255"
    return images.movedim(-1, -3).float() * float(_SCALE)


# ---------------------------------------------------------------------------------------------------
# Distributed setup


@dataclass
class Dist:
    rank: int = 0
    world: int = 1
    local_rank: int = 0
    device: torch.device = torch.device("cpu")

    @property
    def main(self) -> bool:
        return self.rank == 0


def resolve_device(pref: str, local_rank: int = 0) -> torch.device:
    if pref == "auto":
        pref = "cuda" if torch.cuda.is_available() else "cpu"
    if pref == "cuda":
        if not torch.cuda.is_available():
            raise RuntimeError("device 'cuda' requested but torch.cuda.is_available() is False")
        return torch.device("cuda", local_rank)
    return torch.device(pref)


def setup_dist(cfg: TrainConfig) -> Dist:
    """Single process, or the process group torchrun describes in its environment variables."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    device = resolve_device(cfg.device, local_rank)
    if cfg.num_threads > 0:
        torch.set_num_threads(cfg.num_threads)
    if world > 1 and not torch.distributed.is_initialized():
        backend = "nccl" if device.type == "cuda" else "gloo"
        if device.type == "cuda":
            torch.cuda.set_device(device)
        torch.distributed.init_process_group(backend=backend)
    return Dist(rank, world, local_rank, device)


def _barrier(dist: Dist) -> None:
    if dist.world > 1:
        torch.distributed.barrier()


# ---------------------------------------------------------------------------------------------------
# Data


class Windows:
    """The dataset as tensors plus the train/val windows of one length (2 = pairs, N + 1 = triples)."""

    def __init__(self, data: FrameData, length: int, cfg: TrainConfig, dist: Dist) -> None:
        self.length = length
        train_ids, self.val_ids = split_for(data, cfg)  # whole houses held out when there are several
        self.train_starts = window_starts(data.episodes, length, train_ids)
        self.val_starts = window_starts(data.episodes, length, self.val_ids)
        if len(self.train_starts) == 0 or len(self.val_starts) == 0:
            raise DatasetError(
                f"no {length}-frame windows in the {'training' if len(self.train_starts) == 0 else 'validation'}"
                " episodes; record longer episodes or more frames"
            )
        if cfg.data_on_device == "auto":
            on_device = True  # on CPU the "device" is host memory
            if dist.device.type == "cuda":
                free, _ = torch.cuda.mem_get_info(dist.device)
                on_device = data.images.nbytes < 0.25 * free
        else:
            on_device = cfg.data_on_device == "yes"
        self.device = dist.device
        self.on_device = on_device
        target = dist.device if on_device else torch.device("cpu")
        if isinstance(data.images, np.ndarray):
            self.images = torch.from_numpy(data.images).to(target)  # (T, H, W, 3) uint8
        else:  # a sharded dataset (training.shards): frames are gathered per batch from memory maps
            self.images = data.images
        self.commands = torch.from_numpy(data.commands.astype(np.float32)).to(target)  # (T, 2)
        self.pin = not on_device and dist.device.type == "cuda"
        self.mean_command = data.commands[self.train_starts].mean(axis=0).astype(np.float32)

    def gather_raw(self, starts: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """Window starts (B,) -> uint8 frames (B, L, H, W, 3) and commands (B, L-1, 2), where the data lives."""
        idx = torch.as_tensor(starts, dtype=torch.long)[:, None] + torch.arange(self.length)  # (B, L)
        if not isinstance(self.images, torch.Tensor):
            return torch.from_numpy(self.images[idx.numpy()]), self.commands[
                idx[:, :-1].to(self.commands.device)
            ]
        idx = idx.to(self.images.device)
        return self.images[idx], self.commands[idx[:, :-1]]

    def to_device(self, frames: torch.Tensor, commands: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """uint8 frames -> float (B, L, 3, H, W) on the training device (async copy from pinned memory)."""
        frames = frames.to(self.device, non_blocking=True)
        commands = commands.to(self.device, non_blocking=True)
        return images_to_float(frames), commands

    def gather(self, starts: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """Window starts (B,) -> frames (B, L, 3, H, W) float on the device, commands (B, L-1, 2)."""
        return self.to_device(*self.gather_raw(starts))

    def loader(
        self, batches: Iterator[np.ndarray], steps: int, workers: int
    ) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        """Training batches on the device. Data held on the device is indexed in place; otherwise a
        DataLoader gathers batches in ``workers`` processes into pinned memory, overlapping the copy."""
        if self.on_device:
            for _ in range(steps):
                yield self.gather(next(batches))
            return
        plan = [next(batches) for _ in range(steps)]  # the batch order is fixed up front (deterministic)
        dl = torch.utils.data.DataLoader(
            _BatchList(self, plan),
            batch_size=None,
            shuffle=False,
            num_workers=workers,
            pin_memory=self.pin,
            persistent_workers=False,
        )
        for frames, commands in dl:
            yield self.to_device(frames, commands)

    def steps_per_epoch(self, batch: int, world: int) -> int:
        return max(1, len(self.train_starts) // (batch * world))

    def train_batches(self, batch: int, seed: int, start_step: int, dist: Dist) -> Iterator[np.ndarray]:
        """Batches of window starts for steps start_step, start_step+1, ...; a pure function of the step."""
        per_epoch = self.steps_per_epoch(batch, dist.world)
        step = start_step
        while True:
            epoch, k = divmod(step, per_epoch)
            perm = np.random.default_rng([seed, epoch]).permutation(len(self.train_starts))
            if len(perm) < batch * dist.world:  # tiny datasets: repeat the permutation
                perm = np.resize(perm, batch * dist.world)
            mine = perm[dist.rank :: dist.world]
            yield self.train_starts[mine[k * batch : (k + 1) * batch]]
            step += 1

    def val_batches(self, batch: int, limit: int | None) -> Iterator[np.ndarray]:
        n = math.ceil(len(self.val_starts) / batch)
        for k in range(n if limit is None else min(n, limit)):
            yield self.val_starts[k * batch : (k + 1) * batch]


class _BatchList(torch.utils.data.Dataset):
    """Pre-planned batches of window starts, gathered on the host (DataLoader workers)."""

    def __init__(self, windows: Windows, plan: list[np.ndarray]) -> None:
        self.windows, self.plan = windows, plan

    def __len__(self) -> int:
        return len(self.plan)

    def __getitem__(self, k: int) -> tuple[torch.Tensor, torch.Tensor]:
        return self.windows.gather_raw(self.plan[k])


# ---------------------------------------------------------------------------------------------------
# Checkpoints


def atomic_save(obj: Any, path: Path) -> None:
    with atomic_path(path) as tmp:
        torch.save(obj, tmp)


def load_model(
    path: str | os.PathLike, map_location: str | torch.device = "cpu"
) -> tuple[str, nn.Module, dict]:
    """(kind, model in eval mode, the whole file) from a model.pt or checkpoint.pt."""
    path = Path(path)
    if path.is_dir():
        path = path / MODEL
    if not path.is_file():
        raise FileNotFoundError(f"no model checkpoint at {path}")
    ckpt = torch.load(path, map_location=map_location, weights_only=False)
    kind = ckpt.get("kind")
    if kind == "viewnet":
        model: nn.Module = ViewNet(from_dict(ViewNetConfig, ckpt["model_config"]))
    elif kind == "velocitynet":
        model = VelocityNet(from_dict(VelocityNetConfig, ckpt["model_config"]))
    else:
        raise ValueError(f"{path} is not a vtr model checkpoint (kind={kind!r})")
    model.load_state_dict(ckpt["state_dict"])
    return kind, model.eval(), ckpt


# ---------------------------------------------------------------------------------------------------
# The loop


def _jsonable(d: dict[str, Any]) -> dict[str, Any]:
    return {
        k: (round(float(v), 7) if isinstance(v, (float, np.floating, torch.Tensor)) else v)
        for k, v in d.items()
    }


def _fit(
    kind: str,
    model: nn.Module,
    model_cfg: Any,
    loss_fn: Callable[[nn.Module, torch.Tensor, torch.Tensor], tuple[torch.Tensor, dict[str, torch.Tensor]]],
    windows: Windows,
    cfg: TrainConfig,
    dist: Dist,
    out: Path,
    resume: bool,
    extra: dict[str, Any],
) -> nn.Module:
    """Adam on loss_fn for cfg.steps steps; returns the trained (unwrapped) model."""
    from tqdm import tqdm

    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(cfg.seed)
    model.to(dist.device)
    optim = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=cfg.lr)
    step = 0
    ckpt_path = out / CHECKPOINT
    if ckpt_path.exists():
        if not resume:
            raise FileExistsError(
                f"{ckpt_path} exists: pass --resume to continue it, or choose another --out"
            )
        ckpt = torch.load(ckpt_path, map_location=dist.device, weights_only=False)
        if ckpt.get("kind") != kind or ckpt.get("model_config") != to_dict(model_cfg):
            raise ValueError(
                f"{ckpt_path} is a different model ({ckpt.get('kind')}); cannot resume it as {kind}"
            )
        model.load_state_dict(ckpt["state_dict"])
        optim.load_state_dict(ckpt["optimizer"])
        step = int(ckpt["step"])
    net: nn.Module = model
    if dist.world > 1:
        net = nn.parallel.DistributedDataParallel(
            model, device_ids=[dist.device.index] if dist.device.type == "cuda" else None
        )
    amp = cfg.amp and dist.device.type == "cuda"

    def save(at: int) -> None:
        if dist.main:
            atomic_save(
                {
                    "kind": kind,
                    "model_config": to_dict(model_cfg),
                    "train_config": to_dict(cfg),
                    "state_dict": model.state_dict(),
                    "optimizer": optim.state_dict(),
                    "step": at,
                    **extra,
                },
                ckpt_path,
            )

    def log(row: dict[str, Any]) -> None:
        if dist.main:
            with open(out / METRICS, "a") as f:
                f.write(json.dumps(_jsonable(row)) + "\n")

    def validate(limit: int | None) -> dict[str, float]:
        model.eval()
        sums: dict[str, float] = {}
        count = 0
        with torch.no_grad(), torch.autocast("cuda", torch.bfloat16, enabled=amp):
            for starts in windows.val_batches(cfg.batch_size, limit):
                frames, commands = windows.gather(starts)
                loss, parts = loss_fn(model, frames, commands)
                for k, v in {"loss": loss, **parts}.items():
                    if v.ndim == 0:
                        sums[k] = sums.get(k, 0.0) + float(v) * len(starts)
                count += len(starts)
        model.train()
        return {k: v / count for k, v in sums.items()}

    batches = windows.loader(
        windows.train_batches(cfg.batch_size, cfg.seed, step, dist), cfg.steps - step, cfg.num_workers
    )
    bar = tqdm(total=cfg.steps, initial=step, desc=f"train {kind}", disable=not dist.main, dynamic_ncols=True)
    model.train()
    t_start, running, n_running, busy = time.perf_counter(), 0.0, 0, 0.0
    try:
        while step < cfg.steps:
            t0 = time.perf_counter()
            frames, commands = next(batches)
            with torch.autocast("cuda", torch.bfloat16, enabled=amp):
                loss, _ = loss_fn(net, frames, commands)
            optim.zero_grad(set_to_none=True)
            loss.backward()
            optim.step()
            step += 1
            value = float(loss.detach())
            if not math.isfinite(value):
                raise FloatingPointError(f"{kind} loss became {value} at step {step}")
            running, n_running, busy = running + value, n_running + 1, busy + time.perf_counter() - t0
            bar.update(1)
            bar.set_postfix(loss=f"{value:.4f}")
            if step % cfg.log_every == 0 or step == cfg.steps:
                log(
                    {
                        "step": step,
                        "split": "train",
                        "loss": running / n_running,
                        "lr": cfg.lr,
                        "step_time_s": busy / n_running,  # mean over the interval, validation excluded
                        "elapsed_s": time.perf_counter() - t_start,
                    }
                )
                running, n_running, busy = 0.0, 0, 0.0
            if step % cfg.val_every == 0 or step == cfg.steps:
                if dist.main:
                    metrics = validate(cfg.val_batches)
                    log({"step": step, "split": "val", **metrics})
                    bar.write(f"{kind} step {step}: val loss {metrics['loss']:.5f}")
                save(step)
                _barrier(dist)
    except KeyboardInterrupt:
        if step > 0:
            save(step)  # Ctrl-C keeps the progress: --resume continues from this step
            bar.write(f"{kind}: interrupted at step {step}; checkpoint saved, continue with --resume")
        raise
    bar.close()
    model.eval()
    return model


def _finish(
    kind: str, model: nn.Module, model_cfg: Any, out: Path, dist: Dist, extra: dict[str, Any]
) -> None:
    if dist.main:
        atomic_save(
            {
                "kind": kind,
                "model_config": to_dict(model_cfg),
                "state_dict": model.cpu().state_dict(),
                **extra,
            },
            out / MODEL,
        )
        model.to(dist.device)


def _write_report(out: Path, report: dict[str, Any]) -> None:
    from vtr.training.report import format_report

    write_text_atomic(out / REPORT, json.dumps(report, indent=2))
    print(format_report(report))


def train_viewnet(
    data_path: str | os.PathLike,
    out: str | os.PathLike,
    model_cfg: ViewNetConfig,
    cfg: TrainConfig,
    resume: bool = False,
    init: str | os.PathLike | None = None,
) -> dict[str, Any]:
    """Train ViewNet on forward and reversed pairs (from the weights in `init` if given); returns the
    offline quality report."""
    from vtr.training.report import viewnet_report

    out = Path(out)
    dist = setup_dist(cfg)
    data = load_dataset(data_path, image_size=model_cfg.image_size)
    windows = Windows(data, 2, cfg, dist)
    extra = {"data": str(data_path), "data_meta": data.meta, "val_episodes": windows.val_ids.tolist()}
    model = ViewNet(model_cfg)
    if init is not None:
        extra.update(init_weights(model, "viewnet", model_cfg, init))

    def loss_fn(net: nn.Module, frames: torch.Tensor, commands: torch.Tensor):
        loss = viewnet_loss(net, frames, commands[:, 0])
        return loss, {}

    model = _fit("viewnet", model, model_cfg, loss_fn, windows, cfg, dist, out, resume, extra)
    report: dict[str, Any] = {}
    if dist.main:
        report = viewnet_report(model, windows, cfg.batch_size, amp=cfg.amp)
        extra["report"] = report
        _finish("viewnet", model, model_cfg, out, dist, extra)
        _write_report(out, report)
    _barrier(dist)
    return report


def train_velocitynet(
    data_path: str | os.PathLike,
    viewnet_path: str | os.PathLike,
    out: str | os.PathLike,
    model_cfg: VelocityNetConfig,
    loss_cfg: MPCLossConfig,
    cfg: TrainConfig,
    resume: bool = False,
    init: str | os.PathLike | None = None,
) -> dict[str, Any]:
    """Train VelocityNet with the offline MPC loss through a frozen ViewNet (from the weights in `init` if
    given); returns the quality report."""
    from vtr.training.report import velocitynet_report

    out = Path(out)
    dist = setup_dist(cfg)
    if model_cfg.horizon != loss_cfg.horizon:
        raise ValueError(f"VelocityNet horizon {model_cfg.horizon} != MPC loss horizon {loss_cfg.horizon}")
    kind, viewnet, _ = load_model(viewnet_path)
    if kind != "viewnet":
        raise ValueError(f"{viewnet_path} holds a {kind}, not a ViewNet")
    if viewnet.cfg.image_size != model_cfg.image_size:
        raise ValueError(
            f"ViewNet image size {viewnet.cfg.image_size} != VelocityNet's {model_cfg.image_size}"
        )
    viewnet.to(dist.device).eval().requires_grad_(False)  # frozen: eval BN statistics, no weight updates
    data = load_dataset(data_path, image_size=model_cfg.image_size)
    windows = Windows(data, loss_cfg.horizon + 1, cfg, dist)
    extra = {
        "data": str(data_path),
        "data_meta": data.meta,
        "val_episodes": windows.val_ids.tolist(),
        "viewnet": str(viewnet_path),
        "loss_config": to_dict(loss_cfg),
        "mean_command": windows.mean_command.tolist(),
        "preprocessing": PREPROCESSING,
    }
    model = VelocityNet(model_cfg)
    if init is not None:
        extra.update(init_weights(model, "velocitynet", model_cfg, init))

    def loss_fn(net: nn.Module, frames: torch.Tensor, commands: torch.Tensor):
        loss, parts = mpc_loss(net, viewnet, frames, commands, loss_cfg)
        parts.pop("u1")
        return loss, parts

    model = _fit("velocitynet", model, model_cfg, loss_fn, windows, cfg, dist, out, resume, extra)
    report: dict[str, Any] = {}
    if dist.main:
        report = velocitynet_report(model, viewnet, windows, loss_cfg, cfg.batch_size, amp=cfg.amp)
        extra["report"] = report
        _finish("velocitynet", model, model_cfg, out, dist, extra)
        _write_report(out, report)
    _barrier(dist)
    return report
