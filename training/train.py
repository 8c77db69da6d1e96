"""The fit loop for ViewNet and VelocityNet (offline MPC), single process or under torchrun/DDP.

Each stage writes into its output folder (names in ``training.checkpoint``):
    checkpoint.pt   resumable state (model, optimiser, step), rewritten atomically every val_every steps
    model.pt        the trained model (kind, config, weights), written once at the end
    metrics.jsonl   one JSON object per log line (train and val)
    report.json     the offline quality report (training/report.py)

Data windows live in ``training.windows``, the process group in ``training.distributed``, checkpoint
reading and writing in ``training.checkpoint``; this module is only the loop.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from vtr.runtime.atomic import write_text_atomic
from vtr.training.appearances import swap_appearance
from vtr.training.augment import AugmentConfig, InputPipeline
from vtr.training.checkpoint import (
    CHECKPOINT,
    METRICS,
    MODEL,
    REPORT,
    load_model,
    read_checkpoint,
    save_checkpoint,
)
from vtr.training.config import MPCLossConfig, TrainConfig, VelocityNetConfig, ViewNetConfig, to_dict
from vtr.training.consistency import consistency_error, consistency_pairs
from vtr.training.dataset import FrameData, load_dataset
from vtr.training.distributed import Dist, any_rank, barrier, setup_dist
from vtr.training.extra_pairs import JointCall, recovery_batches
from vtr.training.losses import mpc_loss, velocity_error, viewnet_loss
from vtr.training.models import VelocityNet, ViewNet
from vtr.training.transfer import init_viewnet_config, init_weights
from vtr.training.windows import Windows

__all__ = ["CHECKPOINT", "METRICS", "MODEL", "REPORT", "train_velocitynet", "train_viewnet"]


def _jsonable(d: dict[str, Any]) -> dict[str, Any]:
    return {
        k: (round(float(v), 7) if isinstance(v, (float, np.floating, torch.Tensor)) else v)
        for k, v in d.items()
    }


def on_device(model: nn.Module, dist: Dist) -> nn.Module:
    """The model on the training device, its convolutions' weights channels-last: both networks are stacks of
    convolutions, which oneDNN runs faster on that layout (on 2 CPU threads a VelocityNet step through the
    ViewNet roll-out took 0.124 s against 0.152 s; the layout cuDNN's tensor-core kernels prefer too, not
    measured here). Checkpoints are saved contiguous."""
    return model.to(dist.device, memory_format=torch.channels_last)


def _contiguous(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    return {k: v.contiguous() for k, v in state.items()}


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
    on_device(model, dist)
    optim = torch.optim.Adam([p for p in model.parameters() if p.requires_grad], lr=cfg.lr)
    step = 0
    ckpt_path = out / CHECKPOINT
    if ckpt_path.exists():
        if not resume:
            raise FileExistsError(
                f"{ckpt_path} exists: pass --resume to continue it, or choose another --out"
            )
        ckpt = read_checkpoint(ckpt_path, map_location=dist.device)
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
            save_checkpoint(
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
    deadline = t_start + 60.0 * cfg.max_minutes if cfg.max_minutes > 0 else math.inf
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
                if any_rank(dist, time.perf_counter() > deadline) and step < cfg.steps:
                    bar.write(f"{kind}: --max-minutes {cfg.max_minutes:g} reached at step {step}; finishing")
                    log({"step": step, "split": "budget", "max_minutes": cfg.max_minutes})
                    if dist.main:
                        log({"step": step, "split": "val", **validate(cfg.val_batches)})
                    save(step)
                    barrier(dist)
                    break
            if step % cfg.val_every == 0 or step == cfg.steps:
                if dist.main:
                    metrics = validate(cfg.val_batches)
                    log({"step": step, "split": "val", **metrics})
                    bar.write(f"{kind} step {step}: val loss {metrics['loss']:.5f}")
                save(step)
                barrier(dist)
    except KeyboardInterrupt:
        if step > 0:
            save(step)  # Ctrl-C keeps the progress: --resume continues from this step
            bar.write(f"{kind}: interrupted at step {step}; checkpoint saved, continue with --resume")
        raise
    bar.close()
    model.eval()
    extra["steps_done"] = (
        step  # the model's checkpoint says where training stopped (--max-minutes: before steps)
    )
    return model


def _finish(
    kind: str, model: nn.Module, model_cfg: Any, out: Path, dist: Dist, extra: dict[str, Any]
) -> None:
    if dist.main:
        save_checkpoint(
            {
                "kind": kind,
                "model_config": to_dict(model_cfg),
                "state_dict": _contiguous(model.cpu().state_dict()),
                **extra,
            },
            out / MODEL,
        )
        on_device(model, dist)


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
    data: FrameData | None = None,
    init: str | os.PathLike | None = None,
) -> dict[str, Any]:
    """Train ViewNet on forward and reversed pairs; returns the offline quality report.

    ``data``: the dataset at ``data_path`` already loaded (``vtr train all`` loads it once).
    ``init``: start from the weights of this ViewNet checkpoint (fine-tuning, training.transfer)."""
    from vtr.training.report import viewnet_report

    out = Path(out)
    dist = setup_dist(cfg)
    if data is None:
        data = load_dataset(data_path, image_size=model_cfg.image_size)
    windows = Windows(data, 2, cfg, dist)
    extra = {
        "data": str(data_path),
        "data_meta": {**data.meta, "frames": len(data)},  # export records what the model was trained on
        "val_episodes": windows.val_ids.tolist(),
        "train_config": to_dict(cfg),  # kept in model.pt too: export writes the recipe into the ONNX
    }
    if init is not None:
        model_cfg = init_viewnet_config(model_cfg, init)
    torch.manual_seed(cfg.seed)  # the initial weights come from --seed, not from whatever ran before
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
    barrier(dist)
    return report


def train_velocitynet(
    data_path: str | os.PathLike,
    viewnet_path: str | os.PathLike,
    out: str | os.PathLike,
    model_cfg: VelocityNetConfig,
    loss_cfg: MPCLossConfig,
    cfg: TrainConfig,
    resume: bool = False,
    data: FrameData | None = None,
    init: str | os.PathLike | None = None,
    recovery: str | os.PathLike | None = None,
) -> dict[str, Any]:
    """Train VelocityNet with the offline MPC loss through a frozen ViewNet; returns the quality report.

    ``data``: the dataset at ``data_path`` already loaded (``vtr train all`` loads it once).
    ``init``: start from the weights of this VelocityNet checkpoint (fine-tuning, training.transfer).
    ``recovery``: recovery views of this dataset (training.recovery), weighted by ``loss_cfg.w_recovery``."""
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
            f"the ViewNet at {viewnet_path} takes {viewnet.cfg.image_size}px images but this preset's VelocityNet "
            f"takes {model_cfg.image_size}px; train with the preset the ViewNet was trained with (--preset)"
        )
    on_device(viewnet, dist).eval().requires_grad_(False)  # frozen: eval BN statistics, no weight updates
    if data is None:
        data = load_dataset(data_path, image_size=model_cfg.image_size)
    alt = cfg.appearance_swap > 0 or loss_cfg.w_consistency > 0
    windows = Windows(data, loss_cfg.horizon + 1, cfg, dist, alt=alt)
    extra = {
        "data": str(data_path),
        "data_meta": {**data.meta, "frames": len(data)},  # export records what the model was trained on
        "val_episodes": windows.val_ids.tolist(),
        "viewnet": str(viewnet_path),
        "loss_config": to_dict(loss_cfg),
        "mean_command": windows.mean_command.tolist(),
        "preprocessing": model_cfg.preprocessing,
        "augment": cfg.augment,
        "train_config": to_dict(cfg),
    }
    torch.manual_seed(cfg.seed)  # the initial weights come from --seed, not from whatever ran before
    model = VelocityNet(model_cfg)
    if init is not None:
        extra.update(init_weights(model, "velocitynet", model_cfg, init))
    augment = AugmentConfig() if cfg.augment else None
    gen = torch.Generator().manual_seed(cfg.seed + 1)  # augmentation draws, apart from the batch order
    rec = recovery_batches(recovery, data, windows, loss_cfg, cfg, extra)

    def loss_fn(net: nn.Module, frames: torch.Tensor, commands: torch.Tensor):
        policy = InputPipeline(net, model_cfg.preprocessing, augment, gen)  # identity by default
        batch = rec() if rec is not None and net.training else None
        views, goals = ([batch[0]], [batch[1]]) if batch is not None else ([], [])
        stops = max(1, frames.shape[0] // 4) if loss_cfg.w_stop > 0 and net.training else 0
        # a quarter of the batch's first frames paired with themselves (augmented apart: other light)
        if stops:
            views.append(frames[:stops, 0])
            goals.append(frames[:stops, 0])
        other = None
        # training windows in two appearances (training.appearances): pair them with appearance_swap
        if frames.shape[1] == 2 * windows.length:
            frames, other = frames.split(windows.length, dim=1)
        same = max(1, frames.shape[0] // 4) if other is not None and loss_cfg.w_consistency > 0 else 0
        if same:  # the floor-consistency pairs (training.consistency), after the stop pairs
            pairs = consistency_pairs(frames, other, same, loss_cfg.horizon, gen)
            views.append(pairs[0])
            goals.append(pairs[1])
        # Extra pairs ride in the same VelocityNet call as the MPC pairs: one forward per step (DDP).
        joint = JointCall(policy, torch.cat(views), torch.cat(goals)) if views else policy
        subgoals = None
        if other is not None:
            frames, subgoals = swap_appearance(frames, other, cfg.appearance_swap, gen)
        loss, parts = mpc_loss(joint, viewnet, frames, commands, loss_cfg, subgoals)
        parts.pop("u1")
        if batch is not None:
            parts["rec"] = velocity_error(joint.extra[: len(batch[0])], batch[2]).mean()
            loss = loss + loss_cfg.w_recovery * parts["rec"]
        if same:
            parts["same"] = consistency_error(joint.extra[joint.extra.shape[0] - 2 * same :])
            loss = loss + loss_cfg.w_consistency * parts["same"]
        if stops:
            u = joint.extra[joint.extra.shape[0] - 2 * same - stops : joint.extra.shape[0] - 2 * same]
            parts["stop"] = velocity_error(u, torch.zeros_like(u)).mean()
            loss = loss + loss_cfg.w_stop * parts["stop"]
        return loss, parts

    model = _fit("velocitynet", model, model_cfg, loss_fn, windows, cfg, dist, out, resume, extra)
    report: dict[str, Any] = {}
    if dist.main:
        policy = InputPipeline(model, model_cfg.preprocessing)
        report = velocitynet_report(policy, viewnet, windows, loss_cfg, cfg.batch_size, amp=cfg.amp)
        extra["report"] = report
        _finish("velocitynet", model, model_cfg, out, dist, extra)
        _write_report(out, report)
    barrier(dist)
    return report
