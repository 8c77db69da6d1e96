"""The dataset `vtr collect --sim` extends (training.collect_robot): a folder of shards (training.shards) that
grows by whole episodes, the frames recorded since the last shard, and the checks that an existing folder can
be resumed by this run.

Only the frames not yet in a shard are held in memory, and a checkpoint writes only them (plus the index), so
recording costs the same per frame at 100,000 frames as at 1,000. A shard ends at an episode's end: its last
frame carries the zero command, and no episode spans two shards.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vtr.runtime.robot import Observation
from vtr.training.dataset import DatasetError
from vtr.training.shards import ShardAppender


@dataclass
class Recording:
    """The frames since the last shard and what happened while driving; ``store`` holds the rest."""

    store: ShardAppender
    images: list[np.ndarray] = field(default_factory=list)
    commands: list[tuple[float, float]] = field(default_factory=list)
    poses: list[tuple[float, float, float]] = field(default_factory=list)
    episodes: list[int] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)
    episode: int = 0  # the id of the episode being recorded (ids run on over the shards)
    counts: dict[str, int] = field(default_factory=dict)

    @property
    def frames(self) -> int:
        """Frames in the dataset, saved or not."""
        return self.store.frames + len(self.images)

    @property
    def n_episodes(self) -> int:
        return self.store.episodes + len(set(self.episodes))

    def add(self, obs: Observation) -> None:
        self.images.append(np.array(obs.image, dtype=np.uint8, copy=True))
        self.commands.append((0.0, 0.0))  # set when the next frame of the same episode arrives
        self.poses.append(obs.pose if obs.pose is not None else (0.0, 0.0, 0.0))
        self.episodes.append(self.episode)
        if obs.pose is None:
            self.meta["poses_known"] = False

    def end_episode(self) -> None:
        if self.episodes and self.episodes[-1] == self.episode:
            self.episode += 1

    def count(self, key: str) -> None:
        self.counts[key] = self.counts.get(key, 0) + 1

    def save(self, dt: float) -> None:
        """Append every frame held as one shard; the last one ends its episode (its command becomes zero)."""
        if not self.images:
            return
        self.commands[-1] = (0.0, 0.0)
        episodes = np.array(self.episodes, np.int64)
        arrays = {
            "images": np.stack(self.images),
            "commands": np.array(self.commands, np.float32),
            "poses": np.array(self.poses, np.float32),
            "episodes": (episodes - episodes[0]).astype(np.int32),
        }
        self.store.append(arrays, house=str(self.meta.get("map", "robot")), meta=self.meta, dt=dt)
        self.images, self.commands, self.poses, self.episodes = [], [], [], []


def check_out(path: str) -> None:
    """`--sim` records into a folder: a file path (an .npz from an earlier release) is one line."""
    if path.endswith(".npz") or os.path.isfile(path):
        hint = f" ({path} still trains as it is)" if os.path.isfile(path) else ""
        raise DatasetError(
            f"--out {path}: `vtr collect --sim` records into a dataset folder that grows shard by shard, so "
            f"it costs the same at any size; give a folder, e.g. --out {path.removesuffix('.npz')}{hint}"
        )


def load_existing(path: str) -> Recording:
    """The dataset folder at ``path`` as a Recording to extend (its frames stay on disk), or an empty one."""
    check_out(path)
    store = ShardAppender(path)
    if not store.shards and os.path.isdir(path):
        # what a crash before the first index leaves (shard files, temporary files) may be overwritten; not more
        foreign = [n for n in os.listdir(path) if not (n.startswith((".", f"{store.prefix}_")))]
        if foreign:
            raise DatasetError(
                f"--out {path} is a folder that holds no dataset (no index.json, but {foreign[0]}); choose another"
            )
    return Recording(store=store, meta=dict(store.meta), episode=store.episodes)


def check_resumable(rec: Recording, camera: dict[str, Any], dt: float, out: str) -> None:
    store = rec.store
    if not store.shards:
        return
    if store.dt != dt:
        raise DatasetError(f"{out} was recorded with dt={store.dt}, this run uses dt={dt}")
    w, h = camera.get("width"), camera.get("height")
    if None not in (w, h) and (w, h) != (store.image_size, store.image_size):
        raise DatasetError(
            f"{out} holds {store.image_size}x{store.image_size} images, the robot's are {w}x{h}"
        )
