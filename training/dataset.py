"""The recorded dataset: one .npz file, validated on load, split by episodes.

Layout (format version 1), T frames:
    images   (T, H, W, 3) uint8 RGB
    commands (T, 2) float32 (v, w): the command applied for dt after frame t; it moves frame t to
             frame t + 1 when both are in the same episode (the last frame of an episode has zeros)
    poses    (T, 3) float32 ground-truth (x, y, yaw) at frame t
    episodes (T,) int32, non-decreasing, contiguous episode ids
    meta     0-d unicode string: JSON with format_version, dt, seed, map, camera, ... (no pickle)

Pairs and triples (windows of length L) never cross an episode boundary.
"""

from __future__ import annotations

import json
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime.atomic import atomic_path
from vtr.runtime.contracts import CONTROL_DT
from vtr.runtime.npz_guard import NpzTooLargeError, np_load_checked

FORMAT_VERSION = 1
_KEYS = ("images", "commands", "poses", "episodes", "meta")


class DatasetError(ValueError):
    """A dataset file that is missing, corrupt, or does not match what the caller expects."""


@dataclass
class FrameData:
    images: np.ndarray  # (T, H, W, 3) uint8
    commands: np.ndarray  # (T, 2) float32
    poses: np.ndarray  # (T, 3) float32
    episodes: np.ndarray  # (T,) int32
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.images.shape[0])

    @property
    def image_size(self) -> int:
        return int(self.images.shape[1])


def save_dataset(path: str | os.PathLike, data: FrameData) -> None:
    """Write atomically: a temporary file in the same folder, then os.replace. Uncompressed, as routes are:
    loading refuses an archive whose arrays exceed 4x its size (runtime.npz_guard), and compressed frames
    would pass that bound only by luck."""
    validate(data, source=str(path))
    meta = dict(data.meta, format_version=FORMAT_VERSION)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(
            f,
            images=data.images,
            commands=data.commands.astype(np.float32),
            poses=data.poses.astype(np.float32),
            episodes=data.episodes.astype(np.int32),
            meta=np.array(json.dumps(meta, sort_keys=True)),
        )


def load_dataset(path: str | os.PathLike, image_size: int | None = None) -> FrameData:
    """Load and validate; raises DatasetError with a readable message on any problem.

    A folder with an index.json is a sharded dataset (training.shards, from `vtr collect --houses`): it
    opens memory-mapped, its images a lazy array, with per-frame ``houses`` ids."""
    path = Path(path)
    if path.is_dir() and (path / "index.json").is_file():
        from vtr.training.shards import load_sharded  # imports this module: import here, not at the top

        return load_sharded(path, image_size=image_size)
    if not path.is_file():
        raise DatasetError(f"dataset {path} does not exist; record one with `vtr collect --out {path}`")
    try:
        with np_load_checked(path) as z:  # no pickles, and at most 4x the file's size in memory
            missing = [k for k in _KEYS if k not in z.files]
            if missing:
                raise DatasetError(f"dataset {path} lacks arrays {missing}; is it a `vtr collect` file?")
            arrays = {k: z[k] for k in _KEYS}
    except DatasetError:
        raise
    except NpzTooLargeError as err:
        why = str(err).removeprefix(f"{path}: ")
        if "not an .npz archive" in why:
            raise DatasetError(
                f"dataset {path} is corrupt or not a .npz file ({why}); record one with `vtr collect`"
            ) from None
        raise DatasetError(f"dataset {path} refused: {why}") from None
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as err:
        why = "not a NumPy .npz archive" if "pickle" in str(err) else f"{type(err).__name__}: {err}"
        raise DatasetError(
            f"dataset {path} is corrupt or not a .npz file ({why}); record one with `vtr collect`"
        ) from err
    try:
        meta = json.loads(str(arrays["meta"]))
        if not isinstance(meta, dict):
            raise ValueError("not a JSON object")
    except ValueError as err:
        raise DatasetError(f"dataset {path}: metadata is not valid JSON ({err})") from err
    if meta.get("format_version") != FORMAT_VERSION:
        raise DatasetError(
            f"dataset {path} has format version {meta.get('format_version')!r}; this code reads {FORMAT_VERSION}"
        )
    data = FrameData(arrays["images"], arrays["commands"], arrays["poses"], arrays["episodes"], meta)
    validate(data, source=str(path))
    if image_size is not None and data.image_size != image_size:
        raise DatasetError(
            f"dataset {path} has {data.image_size}x{data.image_size} images but the model expects "
            f"{image_size}x{image_size}; use the matching --preset or re-collect"
        )
    return data


def validate(data: FrameData, source: str = "dataset") -> None:
    t = data.images.shape[0] if data.images.ndim == 4 else -1
    if data.images.dtype != np.uint8 or data.images.ndim != 4 or data.images.shape[3] != 3:
        raise DatasetError(
            f"{source}: images must be (T, H, W, 3) uint8, got {data.images.shape} {data.images.dtype}"
        )
    if data.images.shape[1] != data.images.shape[2]:
        raise DatasetError(f"{source}: images must be square, got {data.images.shape[1:3]}")
    if t < 2:
        raise DatasetError(f"{source}: needs at least 2 frames, has {t}")
    for name, shape in (("commands", (t, 2)), ("poses", (t, 3)), ("episodes", (t,))):
        arr = getattr(data, name)
        if arr.shape != shape:
            raise DatasetError(f"{source}: {name} has shape {arr.shape}, expected {shape} for {t} frames")
    if not np.issubdtype(data.episodes.dtype, np.integer):
        raise DatasetError(f"{source}: episodes must be integers, got {data.episodes.dtype}")
    if not (np.isfinite(data.commands).all() and np.isfinite(data.poses).all()):
        raise DatasetError(f"{source}: commands or poses contain NaN/inf")
    if np.any(np.diff(data.episodes) < 0):
        raise DatasetError(
            f"{source}: episode ids must be non-decreasing (each episode one contiguous block)"
        )


def window_starts(episodes: np.ndarray, length: int, allowed: np.ndarray | None = None) -> np.ndarray:
    """Start indices t of windows t .. t+length-1 lying inside one episode (and in ``allowed`` episodes)."""
    t = len(episodes)
    if t < length:
        return np.zeros(0, dtype=np.int64)
    starts = np.arange(t - length + 1)
    ok = episodes[starts] == episodes[starts + length - 1]
    if allowed is not None:
        ok &= np.isin(episodes[starts], allowed)
    return starts[ok]


def split_episodes(episodes: np.ndarray, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(train ids, val ids): whole episodes held out, about val_fraction of the frames, at least one each."""
    ids, counts = np.unique(episodes, return_counts=True)
    if len(ids) < 2:
        raise DatasetError(f"need at least 2 episodes to hold some out for validation, got {len(ids)}")
    order = np.random.default_rng(seed).permutation(len(ids))
    target = val_fraction * counts.sum()
    val: list[int] = []
    total = 0
    for k in order:
        if val and total + counts[k] > target:
            break
        val.append(k)
        total += counts[k]
    val = val[: len(ids) - 1]
    val_ids = np.sort(ids[val])
    return np.setdiff1d(ids, val_ids), val_ids


def synthetic_dataset(frames: int = 64, size: int = 32, episodes: int = 4, seed: int = 0) -> FrameData:
    """A small dataset with learnable motion, for tests and smoke runs (no simulator needed).

    Each frame is a window onto a smooth random panorama; w (rad/s) pans the window horizontally and v
    (m/s) zooms it slightly, so commands and image changes are tied the way a camera's are.
    """
    rng = np.random.default_rng(seed)
    width = 4 * size
    coarse = rng.integers(0, 256, size=(size // 4 + 1, width // 4 + 1, 3)).astype(np.float32)
    pano = np.kron(coarse, np.ones((4, 4, 1), dtype=np.float32))[:size, :width]
    images = np.zeros((frames, size, size, 3), np.uint8)
    commands = np.zeros((frames, 2), np.float32)
    poses = np.zeros((frames, 3), np.float32)
    ids = np.sort(rng.integers(0, episodes, size=frames)).astype(np.int32)
    ids[:episodes] = np.arange(episodes)
    ids = np.sort(ids)
    x = yaw = 0.0
    for t in range(frames):
        if t > 0 and ids[t] != ids[t - 1]:
            x, yaw = 0.0, float(rng.uniform(-np.pi, np.pi))
        poses[t] = (x, 0.0, yaw)
        col = int(round((yaw / (2 * np.pi)) * width)) % width
        rows = np.clip(np.round((np.arange(size) - size / 2) / (1 + 0.2 * x) + size / 2), 0, size - 1).astype(
            int
        )
        cols = (col + np.arange(size)) % width
        images[t] = pano[rows][:, cols].astype(np.uint8)
        v, w = float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-1.0, 1.0))
        last = t == frames - 1 or ids[t + 1] != ids[t]
        commands[t] = (0.0, 0.0) if last else (v, w)
        x, yaw = x + v * CONTROL_DT, yaw + w * CONTROL_DT
    meta = {
        "source": "synthetic",
        "dt": CONTROL_DT,
        "seed": seed,
        "map": "synthetic",
        "camera": {"width": size, "height": size},
    }
    return FrameData(images, commands, poses, ids, meta)
