"""Sharded frame datasets: a folder of per-house .npy shards and a JSON index, read memory-mapped.

Why shards of .npy: a multi-house dataset does not have to fit in memory (1 M frames at 128x128 are 49 GB).
Each collection worker writes its own shards with no coordination; a .npy file is memory-mapped by
``np.load(mmap_mode="r")`` (the OS pages in only the frames a batch touches, no pickle: allow_pickle=False),
whereas an .npz (a zip, compressed) must be decompressed whole. The index is rewritten atomically after
every finished shard, so a crash loses at most the shards being written.

Layout of DIR (format version 1)::

    index.json                 {"format": "vtr-shards", "format_version": 1, "image_size": S, "dt": s,
                                "meta": {...}, "shards": [{"name", "frames", "episodes", "house"}, ...]}
    NAME.images.npy            (T, S, S, 3) uint8
    NAME.commands.npy          (T, 2) float32, as in training/dataset.py (the command after frame t)
    NAME.poses.npy             (T, 3) float32
    NAME.episodes.npy          (T,) int32, 0-based contiguous episode ids within the shard

Episode ids are made global (one running count over the shards, in index order) when the dataset opens,
and each frame carries its house (``houses``: the index of its shard's house in ``house_names``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime.atomic import atomic_path, write_text_atomic
from vtr.training.dataset import DatasetError, FrameData, validate

INDEX = "index.json"
FORMAT = "vtr-shards"
FORMAT_VERSION = 1
ARRAYS = ("images", "commands", "poses", "episodes")
MAX_SHARD_FRAMES = 16384  # a shard is at most this many frames (800 MB at 128x128): files stay manageable


def shard_paths(root: Path, name: str) -> dict[str, Path]:
    return {k: root / f"{name}.{k}.npy" for k in ARRAYS}


def alt_path(root: Path, name: str) -> Path:
    """A shard's optional frames of the same poses in another appearance (training.appearances)."""
    return root / f"{name}.alt_images.npy"


def write_shard(root: str | os.PathLike, name: str, arrays: dict[str, np.ndarray]) -> None:
    """Write one shard's arrays, each atomically (temporary file, then rename)."""
    for key, path in shard_paths(Path(root), name).items():
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.save(f, arrays[key], allow_pickle=False)


def write_index(root: str | os.PathLike, image_size: int, dt: float, meta: dict, shards: list[dict]) -> None:
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "image_size": image_size,
        "dt": dt,
        "meta": meta,
        "shards": shards,
    }
    write_text_atomic(Path(root) / INDEX, json.dumps(doc, indent=1, sort_keys=True) + "\n")


def read_index(root: str | os.PathLike) -> dict | None:
    """The index of the dataset folder ``root`` (checked to be ours), or None when there is none yet."""
    path = Path(root) / INDEX
    if not path.exists():
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise DatasetError(f"dataset {root}: cannot read {INDEX} ({err})") from None
    if (
        not isinstance(doc, dict)
        or doc.get("format") != FORMAT
        or doc.get("format_version") != FORMAT_VERSION
    ):
        raise DatasetError(f"dataset {root}: {INDEX} is not a {FORMAT} version {FORMAT_VERSION} index")
    if not isinstance(doc.get("shards", []), list):
        raise DatasetError(f"dataset {root}: {INDEX} lists no shards")
    return doc


class ShardAppender:
    """Grows a dataset folder one shard at a time (`vtr collect --sim`): an append writes the new shard's files
    and rewrites the index, never an earlier shard, so its cost does not grow with the dataset (the index adds
    about 80 bytes a shard). A crash loses at most the shard being written: the index names only whole shards,
    and a shard whose files were written but not indexed is overwritten by the next run's first append."""

    def __init__(self, root: str | os.PathLike, prefix: str = "part") -> None:
        self.root, self.prefix = Path(root), prefix
        doc = read_index(root) or {}
        self.shards: list[dict] = list(doc.get("shards", []))
        self.meta: dict = dict(doc.get("meta", {}))
        self.image_size: int | None = doc.get("image_size")
        self.dt: float | None = doc.get("dt")
        self.frames = sum(int(e.get("frames", 0)) for e in self.shards)
        self.episodes = sum(int(e.get("episodes", 0)) for e in self.shards)

    def append(self, arrays: dict[str, np.ndarray], house: str, meta: dict, dt: float) -> None:
        """Write one shard (``ARRAYS``; episode ids contiguous within it), then the index naming it."""
        images, episodes = arrays["images"], arrays["episodes"]
        if self.image_size is None:
            self.image_size = int(images.shape[1])
        self.root.mkdir(parents=True, exist_ok=True)
        name = f"{self.prefix}_{len(self.shards):06d}"
        write_shard(self.root, name, arrays)
        n_episodes = int(episodes[-1] - episodes[0]) + 1
        self.shards.append({"name": name, "frames": len(images), "episodes": n_episodes, "house": house})
        self.meta, self.dt = dict(meta), dt
        self.frames += len(images)
        self.episodes += n_episodes
        write_index(self.root, self.image_size, dt, self.meta, self.shards)


class ShardedImages:
    """The images of all shards as one lazy (T, S, S, 3) uint8 array: indexing gathers from memory maps."""

    def __init__(self, maps: list[np.ndarray]) -> None:
        self._maps = maps
        self._ends = np.cumsum([len(m) for m in maps])
        first = maps[0]
        self.shape = (int(self._ends[-1]),) + tuple(first.shape[1:])
        self.dtype = first.dtype
        self.ndim = first.ndim

    def __len__(self) -> int:
        return self.shape[0]

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape)) * self.dtype.itemsize

    def __getitem__(self, idx: Any) -> np.ndarray:
        if isinstance(idx, slice):
            idx = np.arange(*idx.indices(self.shape[0]))
        arr = np.asarray(idx)
        if arr.ndim == 0:
            return self[arr.reshape(1)][0]
        flat = arr.reshape(-1).astype(np.int64)
        if flat.size and (flat.min() < -self.shape[0] or flat.max() >= self.shape[0]):
            raise IndexError(f"frame index out of range for {self.shape[0]} frames")
        flat = np.where(flat < 0, flat + self.shape[0], flat)
        out = np.empty((flat.size,) + self.shape[1:], dtype=self.dtype)
        shard = np.searchsorted(self._ends, flat, side="right")
        starts = np.concatenate([[0], self._ends[:-1]])
        for s in np.unique(shard):
            sel = np.flatnonzero(shard == s)
            local = flat[sel] - starts[s]
            order = np.argsort(local, kind="stable")  # ascending reads are kinder to the page cache
            out[sel[order]] = self._maps[s][local[order]]
        return out.reshape(arr.shape + self.shape[1:])

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        full = self[np.arange(self.shape[0])]
        return full if dtype is None else full.astype(dtype)


def is_sharded(path: str | os.PathLike) -> bool:
    return (Path(path) / INDEX).is_file()


def load_sharded(path: str | os.PathLike, image_size: int | None = None) -> FrameData:
    """Open a sharded dataset: images memory-mapped (lazy), the small arrays in memory; validated.

    The returned FrameData has three extra attributes: ``houses`` (T,) int32, ``house_names`` (list) and
    ``alt_images`` (the frames in another appearance, lazy like the images, or None: training.appearances)."""
    root = Path(path)
    doc = read_index(root)
    if doc is None:
        raise DatasetError(f"dataset {root}: {INDEX} is missing")
    shards = doc.get("shards") or []
    if not shards:
        raise DatasetError(f"dataset {root}: the index lists no shards (collection unfinished?)")
    if not isinstance(shards, list) or not all(
        isinstance(e, dict) and isinstance(e.get("name"), str) for e in shards
    ):
        raise DatasetError(
            f'dataset {root}: {INDEX} lists shards that are not {{"name": ..., "frames": ...}}'
        )
    house_names: list[str] = []
    maps, alt_maps, small = [], [], {k: [] for k in ARRAYS[1:]}
    houses, episode_offset = [], 0
    for entry in shards:
        paths = shard_paths(root, str(entry["name"]))
        try:
            arrays = {k: np.load(p, mmap_mode="r", allow_pickle=False) for k, p in paths.items()}
        except (OSError, ValueError) as err:
            raise DatasetError(
                f"dataset {root}: shard {entry['name']} is missing or corrupt ({err})"
            ) from None
        n = len(arrays["images"]) if all(a.ndim for a in arrays.values()) else 0
        if n < 1 or n != entry.get("frames") or any(len(a) != n for a in arrays.values()):
            raise DatasetError(
                f"dataset {root}: shard {entry['name']} does not hold {entry.get('frames')} frames"
            )
        maps.append(arrays["images"])
        alt = alt_path(root, str(entry["name"]))
        alt_maps.append(np.load(alt, mmap_mode="r", allow_pickle=False) if alt.is_file() else None)
        if alt_maps[-1] is not None and alt_maps[-1].shape != arrays["images"].shape:
            raise DatasetError(
                f"dataset {root}: shard {entry['name']}'s other-appearance frames differ in shape"
            )
        small["commands"].append(np.asarray(arrays["commands"], dtype=np.float32))
        small["poses"].append(np.asarray(arrays["poses"], dtype=np.float32))
        eps = np.asarray(arrays["episodes"], dtype=np.int64)
        small["episodes"].append(eps - eps[0] + episode_offset)
        episode_offset += int(eps[-1] - eps[0]) + 1
        house = str(entry.get("house", "?"))
        if house not in house_names:
            house_names.append(house)
        houses.append(np.full(n, house_names.index(house), dtype=np.int32))
    data = FrameData(
        ShardedImages(maps),  # type: ignore[arg-type]
        np.concatenate(small["commands"]),
        np.concatenate(small["poses"]),
        np.concatenate(small["episodes"]).astype(np.int32),
        dict(doc.get("meta", {}), dt=doc.get("dt"), sharded=True, houses=house_names),
    )
    validate(data, source=str(root))
    if image_size is not None and data.image_size != image_size:
        raise DatasetError(
            f"dataset {root} has {data.image_size}x{data.image_size} images but the model expects "
            f"{image_size}x{image_size}; use the matching --preset or re-collect"
        )
    # every shard with its other appearance, or none used (a partly re-collected folder is not mixed)
    data.alt_images = ShardedImages(alt_maps) if all(m is not None for m in alt_maps) else None  # type: ignore
    data.houses = np.concatenate(houses)  # type: ignore[attr-defined]
    data.house_names = house_names  # type: ignore[attr-defined]
    return data
