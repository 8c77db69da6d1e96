"""`vtr collect --bag`: a training dataset from teleoperated drives recorded in ROS bags (training/bag_read.py).

Each gap-free segment of the resampled drive becomes an episode (a pair never spans a gap); the last frame of an
episode gets a zero command, as in every dataset. Segments shorter than ``MIN_EPISODE`` frames are dropped.
"""

from __future__ import annotations

import json
import sys
from typing import Any

import numpy as np

from vtr.training.bag_read import BagDrive, BagError, read_bag_args
from vtr.training.dataset import FORMAT_VERSION, FrameData, save_dataset

#: Segments shorter than this (frames) make no useful training windows.
MIN_EPISODE = 3


def dataset_from_drive(drive: BagDrive, camera: dict[str, Any] | None = None) -> FrameData:
    """The drive as FrameData (episodes = segments); BagError when nothing is left."""
    keep = np.zeros(len(drive), bool)
    ids, counts = np.unique(drive.segments, return_counts=True)
    for seg, n in zip(ids, counts, strict=True):
        if n >= MIN_EPISODE:
            keep |= drive.segments == seg
        else:
            reason = f"frames in segments shorter than {MIN_EPISODE} frames"
            drive.skipped[reason] = drive.skipped.get(reason, 0) + int(n)
    if keep.sum() < 2:
        raise BagError("the bag gave fewer than 2 usable frames:\n" + drive.report())
    segments = drive.segments[keep]
    episodes = np.cumsum(np.r_[0, np.diff(segments) != 0]).astype(np.int32)
    commands = drive.commands[keep].astype(np.float32)
    last = np.r_[episodes[1:] != episodes[:-1], True]
    commands[last] = 0.0
    poses = drive.poses[keep]
    known = bool(np.isfinite(poses).all())
    meta = {
        "source": "vtr collect --bag",
        "format_version": FORMAT_VERSION,
        "dt": drive.dt,
        "map": "bag",
        "camera": camera if camera is not None else drive.camera(),
        "bag": drive.source,
        "skipped": drive.skipped,
        "poses_known": known,
    }
    return FrameData(drive.images[keep], commands, np.nan_to_num(poses).astype(np.float32), episodes, meta)


def run_cli(args: Any) -> int:
    """`vtr collect --bag PATH --image-topic T --cmd-topic T [--odom-topic T] --out data.npz`."""
    try:
        drive = read_bag_args(args, 0.1, args.image_size)
        for warning in drive.warnings:
            print(f"vtr collect: warning: {warning}", file=sys.stderr)
        data = dataset_from_drive(drive, drive.camera(args.camera_fov, args.camera_height))
        save_dataset(args.out, data)
    except (BagError, OSError) as exc:
        print(f"vtr collect: {exc}", file=sys.stderr)
        return 2
    print(drive.report())
    summary = {
        "out": args.out,
        "frames": len(data),
        "episodes": int(data.episodes.max()) + 1,
        "skipped": drive.skipped,
    }
    print(json.dumps(summary, indent=2))
    return 0
