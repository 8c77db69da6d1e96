"""Extra (view, goal) pairs that ride in the MPC loss's VelocityNet call: recovery views and the stop term.

One forward per training step keeps DistributedDataParallel happy and is faster than a second call.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np
import torch
from torch import nn

from vtr.training.config import MPCLossConfig, TrainConfig
from vtr.training.dataset import FrameData
from vtr.training.windows import Windows


class JointCall:
    """VelocityNet on the MPC loss's pairs plus extra (view, goal) pairs in one batch; keeps the extra output."""

    def __init__(self, policy: nn.Module, views: torch.Tensor, goals: torch.Tensor) -> None:
        self.policy, self.views, self.goals = policy, views, goals
        self.extra = torch.empty(0)

    def __call__(self, current: torch.Tensor, subgoal: torch.Tensor) -> torch.Tensor:
        b = current.shape[0]
        u = self.policy(torch.cat([current, self.views]), torch.cat([subgoal, self.goals]))
        self.extra = u[b:]
        return u[:b]


def recovery_batches(
    path: str | os.PathLike | None,
    data: FrameData,
    windows: Windows,
    loss_cfg: MPCLossConfig,
    cfg: TrainConfig,
    extra: dict[str, Any],
) -> Callable[[], tuple[torch.Tensor, torch.Tensor, torch.Tensor]] | None:
    """A draw of recovery (views, goal frames, labels) per call, from training episodes only; None if off."""
    if path is None or loss_cfg.w_recovery <= 0:
        if path is not None:
            raise ValueError(
                "recovery views were given but the loss weight w_recovery is 0; pass --w-recovery"
            )
        return None
    from vtr.training.recovery import load_recovery
    from vtr.training.windows import images_to_float

    rec = load_recovery(path, data)
    usable = np.flatnonzero(np.isin(rec.starts, windows.train_starts))  # validation houses stay unseen
    if rec.commands.shape[1] != loss_cfg.horizon or len(usable) == 0:
        raise ValueError(
            f"recovery views {path}: none usable for horizon {loss_cfg.horizon} in training episodes"
        )
    extra.update(recovery=str(path), recovery_views=int(len(usable)), recovery_config=rec.config)
    size = max(1, cfg.batch_size // 2)
    rng = np.random.default_rng([cfg.seed, 97])
    labels = torch.from_numpy(rec.commands)

    def draw() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        pick = np.sort(rng.choice(usable, size=size, replace=len(usable) < size))
        views = torch.from_numpy(np.asarray(rec.images[pick]))
        goals = windows.images[rec.starts[pick] + loss_cfg.horizon]
        goals = goals if isinstance(goals, torch.Tensor) else torch.from_numpy(goals)
        dev = windows.device
        return (
            images_to_float(views.to(dev)),
            images_to_float(goals.to(dev)),
            labels[pick].transpose(1, 2).to(dev),  # (B, 2, N) as VelocityNet outputs
        )

    return draw
