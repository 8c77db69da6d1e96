"""The dataset `vtr collect --sim` extends (training.collect_robot): the frames so far, those already in the
file first, and the checks that an existing file can be resumed by this run."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vtr.runtime.robot import Observation
from vtr.training.dataset import DatasetError, FrameData, load_dataset


@dataclass
class Recording:
    """Frames so far (those already in the file first) and what happened while driving."""

    images: list[np.ndarray] = field(default_factory=list)
    commands: list[tuple[float, float]] = field(default_factory=list)
    poses: list[tuple[float, float, float]] = field(default_factory=list)
    episodes: list[int] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)
    episode: int = 0
    counts: dict[str, int] = field(default_factory=dict)

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

    def to_frame_data(self) -> FrameData:
        return FrameData(
            np.stack(self.images),
            np.array(self.commands, np.float32),
            np.array(self.poses, np.float32),
            np.array(self.episodes, np.int32),
            dict(self.meta),
        )


def load_existing(path: str) -> Recording:
    """The dataset already at ``path`` as a Recording to extend, or an empty one."""
    try:
        data = load_dataset(path)
    except DatasetError:
        import os

        if os.path.exists(path):
            raise
        return Recording()
    rec = Recording(
        images=list(data.images),
        commands=[tuple(c) for c in data.commands],
        poses=[tuple(p) for p in data.poses],
        episodes=[int(e) for e in data.episodes],
        meta=dict(data.meta),
    )
    rec.episode = int(data.episodes.max()) + 1
    return rec


def check_resumable(rec: Recording, camera: dict[str, Any], dt: float, out: str) -> None:
    if not rec.images:
        return
    if rec.meta.get("dt") != dt:
        raise DatasetError(f"{out} was recorded with dt={rec.meta.get('dt')}, this run uses dt={dt}")
    size = camera.get("width"), camera.get("height")
    if rec.images[0].shape[:2] != (size[1], size[0]) and None not in size:
        raise DatasetError(
            f"{out} holds {rec.images[0].shape[1]}x{rec.images[0].shape[0]} images, the robot's are {size[0]}x{size[1]}"
        )
