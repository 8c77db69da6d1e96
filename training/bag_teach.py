"""`vtr teach --bag`: a route from a teleoperated drive recorded in a ROS bag (see training/bag_read.py).

The drive is resampled to the control step dt; subgoals follow the same spacing rules as `vtr teach` on a live
robot (runtime/teach.py). A route is one continuous drive: when the bag has gaps, the longest segment is used
(``--segment`` picks another) and the report says so.
"""

from __future__ import annotations

import os
import sys
from typing import Any

import numpy as np

from vtr.runtime.robot import Observation
from vtr.runtime.route import Route
from vtr.runtime.teach import TeachConfig
from vtr.training import bag_read
from vtr.training.bag_read import BagDrive, BagError, read_bag_args


def route_from_drive(
    drive: BagDrive,
    cfg: TeachConfig,
    segment: int | None = None,
    name: str = "bag",
    camera: dict[str, Any] | None = None,
) -> Route:
    """Subgoals from one segment of ``drive`` by ``cfg``'s spacing rule; the first and last frames always."""
    if len(drive) == 0:
        raise BagError("the bag gave no usable frames:\n" + drive.report())
    ids, counts = np.unique(drive.segments, return_counts=True)
    segment = int(ids[np.argmax(counts)]) if segment is None else segment
    if segment not in ids:
        raise BagError(f"no segment {segment}; the bag has segments {ids.min()}..{ids.max()}")
    frames = np.flatnonzero(drive.segments == segment)
    if len(frames) < 2:
        raise BagError(f"segment {segment} has {len(frames)} frame; a route needs 2 or more")
    poses = drive.poses[frames]

    def obs(k: int) -> Observation:
        pose = poses[k]
        return Observation(
            drive.images[frames[k]], k * drive.dt, tuple(pose) if np.isfinite(pose).all() else None
        )

    chosen, since = [0], 0
    for k in range(1, len(frames)):
        since += 1
        last = chosen[-1]
        if cfg.subgoal_due(since, obs(k), drive.images[frames[last]], tuple(poses[last])):
            chosen.append(k)
            since = 0
    if chosen[-1] != len(frames) - 1:
        chosen.append(len(frames) - 1)
    commands = drive.commands[frames[chosen]].copy()
    commands[-1] = 0.0
    return Route(
        images=drive.images[frames[chosen]],
        poses=poses[chosen],
        commands=commands,
        name=name,
        camera=camera if camera is not None else drive.camera(),
        spacing=cfg.rule(),
        map=None,
        dt=drive.dt,
    )


def add_arguments(parser: Any) -> None:
    bag_read.add_arguments(parser, "a route from a teleoperated drive")
    parser.add_argument(
        "--segment",
        type=int,
        default=None,
        help="--bag: which gap-free segment to use (default: the longest)",
    )


def run_cli(args: Any, cfg: TeachConfig) -> int:
    """`vtr teach --bag ... --out route.npz`."""
    if cfg.spacing == "distance" and not args.odom_topic:
        print("vtr teach: --spacing distance needs poses: give --odom-topic", file=sys.stderr)
        return 2
    try:
        drive = read_bag_args(args, cfg.dt, getattr(args, "image_size", 128))
        for warning in drive.warnings:
            print(f"vtr teach: warning: {warning}", file=sys.stderr)
        print(drive.report())
        name = os.path.splitext(os.path.basename(args.out))[0]
        camera = drive.camera(args.camera_fov, args.camera_height)
        if "fov_deg" in camera.get("unknown", ()):
            print(
                "vtr teach: warning: the bag has no calibrated sensor_msgs/CameraInfo for the camera and no "
                "--camera-fov was given: the route records its field of view as unknown, and `vtr repeat` "
                "refuses it; pass --camera-fov DEG",
                file=sys.stderr,
            )
        route = route_from_drive(drive, cfg, args.segment, name=name, camera=camera)
        route.save(args.out)
    except (BagError, OSError) as exc:
        print(f"vtr teach: {exc}", file=sys.stderr)
        return 2
    known = "with poses" if np.isfinite(route.poses).all() else "without poses"
    print(f"vtr teach: {len(route)} subgoals ({cfg.spacing} spacing, {known}) -> {os.path.abspath(args.out)}")
    return 0
