"""The dataset as training windows: tensors on the right device, the train/validation split by episode,
and batches that are a pure function of (seed, step, rank), so a resumed run sees the batches it would have."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import torch

from vtr.runtime.preprocess import PREPROCESSING
from vtr.training.config import TrainConfig
from vtr.training.dataset import DatasetError, FrameData, window_starts
from vtr.training.distributed import Dist
from vtr.training.transfer import split_for

_SCALE = np.float32(1.0 / 255.0)


def images_to_float(images: torch.Tensor) -> torch.Tensor:
    """uint8 (..., H, W, 3) -> float32 (..., 3, H, W) in [0, 1]: runtime.preprocess.to_nchw in torch.

    Kept bit-identical to ``to_nchw`` (a test checks) so training and the runtime cannot drift.
    """
    assert PREPROCESSING == "rgb8_hwc_to_float32_nchw_div255"
    return images.movedim(-1, -3).float() * float(_SCALE)


class Windows:
    """The dataset as tensors plus the train/val windows of one length (2 = pairs, N + 1 = triples)."""

    def __init__(self, data: FrameData, length: int, cfg: TrainConfig, dist: Dist, alt: bool = False) -> None:
        """``alt``: training batches carry the same windows in another appearance too (training.appearances):
        frames (B, 2L, ...), the other appearance after the recorded one; validation stays recorded only."""
        self.length = length
        self.alt_images = getattr(data, "alt_images", None) if alt else None
        if alt and self.alt_images is None:
            raise DatasetError(
                "the dataset holds no frames in another appearance; collect it with `vtr collect --houses ... "
                "--appearances K` or train without --appearance-swap"
            )
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
        if not isinstance(data.images, np.ndarray):
            # a sharded dataset's frames are gathered from memory maps on the host, so its commands stay there
            # too: DataLoader workers (forked) index both, and a forked process cannot touch CUDA tensors
            on_device = False
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

    def gather_raw(self, starts: np.ndarray, alt: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """Window starts (B,) -> uint8 frames (B, L, H, W, 3) and commands (B, L-1, 2), where the data lives;
        ``alt`` (with other-appearance frames): frames (B, 2L, H, W, 3), the other appearance second."""
        idx = torch.as_tensor(starts, dtype=torch.long)[:, None] + torch.arange(self.length)  # (B, L)
        if not isinstance(self.images, torch.Tensor):
            frames = torch.from_numpy(self.images[idx.numpy()])
            if alt and self.alt_images is not None:
                frames = torch.cat([frames, torch.from_numpy(self.alt_images[idx.numpy()])], dim=1)
            return frames, self.commands[idx[:, :-1].to(self.commands.device)]
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
        if self.on_device and self.alt_images is None:
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
        return self.windows.gather_raw(self.plan[k], alt=True)
