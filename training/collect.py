"""`vtr collect`: drive the simulated robot through the house and record a training dataset.

    vtr collect --out data/house.npz --frames 7024 --seed 0 [--noise 0.05]
    vtr collect --houses 40 --frames-per-house 2000 --out data/houses [--workers 2]   (training.collect_houses)

Every dt (0.1 s) it records the camera image, the command applied next (which moves this frame to the
next one), and the ground-truth pose. Episodes start at a random free pose in each room in turn and
hold each command for a few frames: pure translations (forwards and some backwards), pure rotations
both ways, combined arcs and a few stops. A kinematic look-ahead with ``house.is_free`` refuses a
command that would bring the robot within ``robot_radius`` of an obstacle and turns it in place
instead, so the robot works close to walls without touching them; should a step still collide, the
episode ends there (a collided step does not follow the command and would poison the pairs).
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vtr.runtime.kinematics import unicycle
from vtr.training.config import CollectConfig, MPCLossConfig

#: The fewest frames a dataset can be trained on: training holds whole episodes out for validation, so it needs
#: two episodes with a window of N + 1 frames each (training.windows), and the first episode may take up to
#: episode_max frames.
MIN_FRAMES = CollectConfig.episode_max + MPCLossConfig.horizon + 1

_KINDS = ("translate", "rotate", "combined", "stop", "creep", "fast_arc")
# Command mixes (probabilities over _KINDS). "paper": the recipe of the shipped model. "repeat": what the
# controller meets when repeating a route: turns in place, creeping near goals, fast arcs, reversing.
MIXES = {
    "paper": (0.3, 0.3, 0.35, 0.05, 0.0, 0.0),
    "repeat": (0.2, 0.2, 0.25, 0.05, 0.15, 0.15),
}


def arc_points(x: float, y: float, yaw: float, v: float, w: float, horizon: float, samples: int = 4) -> list:
    """Unicycle positions along (v, w) at ``samples`` times in (0, horizon]."""
    return [unicycle(x, y, yaw, v, w, horizon * k / samples)[:2] for k in range(1, samples + 1)]


def sample_command(rng: np.random.Generator, cfg: CollectConfig) -> tuple[str, float, float]:
    kind = str(rng.choice(_KINDS, p=MIXES[cfg.mix]))
    sign_v = -1.0 if rng.random() < cfg.reverse_fraction else 1.0
    sign_w = -1.0 if rng.random() < 0.5 else 1.0
    v = sign_v * float(rng.uniform(0.05, 1.0)) * cfg.v_max
    w = sign_w * float(rng.uniform(0.05, 1.0)) * cfg.w_max
    if kind == "creep":  # a few cm/s with a slight turn: the last centimetres before a subgoal
        return kind, sign_v * float(rng.uniform(0.04, 0.16)) * cfg.v_max, sign_w * float(rng.uniform(0, 0.15))
    if kind == "fast_arc":
        return (
            kind,
            sign_v * float(rng.uniform(0.7, 1.0)) * cfg.v_max,
            sign_w * float(rng.uniform(0.5, 1.0)) * cfg.w_max,
        )
    if kind == "translate":
        return kind, v, 0.0
    if kind == "rotate":
        return kind, 0.0, w
    if kind == "combined":
        return kind, v, w
    return kind, 0.0, 0.0


def sample_pose(house: Any, room: Any, rng: np.random.Generator, radius: float, tries: int = 500) -> tuple:
    lo, hi = room.polygon.min(axis=0), room.polygon.max(axis=0)
    for _ in range(tries):
        x, y = rng.uniform(lo, hi)
        if house.room_at(x, y) == room.name and house.is_free(x, y, radius):
            return float(x), float(y), float(rng.uniform(-math.pi, math.pi))
    raise RuntimeError(f"could not find a free pose in room {room.name!r} for a robot of radius {radius} m")


@dataclass
class Recording:
    """Where drive() writes frames (arrays of the same length, possibly memory-mapped) and its tallies."""

    images: np.ndarray
    commands: np.ndarray
    poses: np.ndarray
    episodes: np.ndarray
    kinds: dict[str, int] = field(default_factory=lambda: dict.fromkeys((*_KINDS, "escape"), 0))
    rooms: dict[str, int] = field(default_factory=dict)
    collisions: int = 0
    n_episodes: int = 0


def drive(
    sim: Any, cfg: CollectConfig, rng: np.random.Generator, rec: Recording, on_frame: Any = None
) -> None:
    """Drive `sim` through its house's rooms in episodes, filling every frame of `rec`.

    Episodes start at a random free pose in each room in turn; `on_frame()` is called after each frame."""
    from vtr.sim2d import Pose

    house = sim.house
    min_radius = max(cfg.robot_radius, sim.cfg.robot_radius)
    radius = min_radius
    n = len(rec.images)
    commands = rec.commands
    commands[:] = 0.0

    def safe(p: Any, v: float, w: float) -> bool:
        pts = arc_points(p.x, p.y, p.yaw, v, w, cfg.dt + cfg.lookahead)
        return bool(np.all(house.clearances(np.asarray(pts)) >= radius))

    image = None
    fresh_start = True
    t, ep = 0, 0
    while t < n:
        if fresh_start:
            radius = float(rng.uniform(min_radius, max(min_radius, cfg.far_clearance)))
            room = house.rooms[ep % len(house.rooms)]
            try:
                start = sample_pose(house, room, rng, radius)
            except RuntimeError:  # a small furnished room: fall back to the least clearance
                radius = min_radius
                start = sample_pose(house, room, rng, radius)
            image = sim.reset(pose=Pose(*start), seed=cfg.seed * 1_000_003 + ep)
        length = int(rng.integers(cfg.episode_min, cfg.episode_max + 1))
        remaining = 0
        kind, v, w = "stop", 0.0, 0.0
        fresh_start = True
        for k in range(length):
            pose = sim.pose
            if remaining == 0:
                kind, v, w = sample_command(rng, cfg)
                remaining = int(rng.integers(cfg.segment_min, cfg.segment_max + 1))
            if not safe(pose, v, w):
                for _ in range(10):
                    kind, v, w = sample_command(rng, cfg)
                    if safe(pose, v, w):
                        break
                else:  # turning in place is always free for a round robot
                    kind, v, w = "escape", 0.0, (1.0 if rng.random() < 0.5 else -1.0) * cfg.w_max * 0.8
            remaining -= 1
            rec.images[t], rec.poses[t], rec.episodes[t] = image, pose, ep
            room_name = house.room_at(pose.x, pose.y) or "?"
            rec.rooms[room_name] = rec.rooms.get(room_name, 0) + 1
            t += 1
            if on_frame is not None:
                on_frame()
            if k == length - 1 or t == n:
                break  # last frame of the episode: its command stays zero
            commands[t - 1] = (v, w)
            rec.kinds[kind] += 1
            image = sim.step(v, w, cfg.dt)
            if sim.collided:
                # The step did not follow the command: cut the pair, start a new episode from here.
                commands[t - 1] = 0.0
                rec.collisions += 1
                fresh_start = False
                break
        ep += 1
    rec.n_episodes = ep


def run(cfg: CollectConfig) -> dict[str, Any]:
    """Drive, record and write the dataset atomically; returns a summary."""
    from tqdm import tqdm

    from vtr.sim2d import CameraConfig, SimConfig, Simulator
    from vtr.training.dataset import FORMAT_VERSION, FrameData, save_dataset

    sim_cfg = SimConfig(camera=CameraConfig(width=cfg.image_size, height=cfg.image_size), noise=cfg.noise)
    sim = Simulator(sim_cfg)
    n = cfg.frames
    rec = Recording(
        np.zeros((n, cfg.image_size, cfg.image_size, 3), np.uint8),
        np.zeros((n, 2), np.float32),
        np.zeros((n, 3), np.float32),
        np.zeros(n, np.int32),
    )
    bar = tqdm(total=n, desc="collect", disable=not cfg.progress, dynamic_ncols=True)
    drive(sim, cfg, np.random.default_rng(cfg.seed), rec, on_frame=lambda: bar.update(1))
    bar.close()
    meta = {
        "source": "vtr collect",
        "format_version": FORMAT_VERSION,
        "dt": cfg.dt,
        "seed": cfg.seed,
        "noise": cfg.noise,
        "map": sim.house.name,
        "camera": sim.info().get("camera", {}),
        "robot_radius": sim_cfg.robot_radius,
        "collect_config": {k: v for k, v in vars(cfg).items() if k != "progress"},
    }
    save_dataset(cfg.out, FrameData(rec.images, rec.commands, rec.poses, rec.episodes, meta))
    return {
        "out": cfg.out,
        "frames": n,
        "episodes": rec.n_episodes,
        "collisions": rec.collisions,
        "commands": rec.kinds,
        "rooms": rec.rooms,
    }


def _range(text: str) -> tuple[float, float]:
    """``A:B`` -> (A, B), A <= B (a one-line argparse error otherwise)."""
    try:
        lo, hi = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected A:B (numbers), got {text!r}") from None
    if not lo <= hi:
        raise argparse.ArgumentTypeError(f"expected A <= B, got {text!r}")
    return lo, hi


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--out",
        default=None,
        help="dataset: a file (.npz, written atomically; default data/house.npz) or, with --houses and --sim, "
        "a folder of shards (default data/houses, data/robot)",
    )
    parser.add_argument(
        "--frames",
        type=int,
        default=7024,
        help=f"frames to record (default and the paper's: 7024; at least {MIN_FRAMES})",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="seed for start poses, commands and actuation noise (default: 0)"
    )
    parser.add_argument(
        "--noise",
        nargs="?",
        type=float,
        const=0.05,
        default=0.0,
        help="actuation noise level (SimConfig.noise); --noise alone means 0.05 (default: 0, off)",
    )
    parser.add_argument("--image-size", type=int, default=128, help="camera width = height (default: 128)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    houses = parser.add_argument_group("across procedural houses (a sharded dataset folder as --out)")
    houses.add_argument(
        "--houses", type=int, default=0, help="record houses random:0 .. random:N-1 (default: off)"
    )
    houses.add_argument(
        "--house-seeds", default=None, metavar="A:B", help="record houses random:A .. random:B-1"
    )
    houses.add_argument(
        "--frames-per-house",
        type=int,
        default=0,
        help="frames per house (default: --frames / number of houses)",
    )
    houses.add_argument(
        "--include-house",
        action="append",
        metavar="NAME",
        help="also record this named map, e.g. `house` (the paper-style house); repeatable",
    )
    houses.add_argument(
        "--include-house-frames",
        type=int,
        default=0,
        help="frames per --include-house map (default 0: --frames-per-house)",
    )
    houses.add_argument(
        "--workers", type=int, default=0, help="worker processes (default 0: one per CPU core)"
    )
    houses.add_argument(
        "--appearances",
        type=int,
        default=0,
        metavar="K",
        help="render every frame again in one of K versions of its house with the floor laid again, for "
        "training with --appearance-swap (training/appearances.py; 0: none) (default: 0)",
    )
    houses.add_argument(
        "--fov-range",
        type=_range,
        default=None,
        metavar="A:B",
        help="cameras across houses: each house's horizontal field of view drawn from A..B degrees "
        "(default: none, the shipped 90)",
    )
    houses.add_argument(
        "--height-range",
        type=_range,
        default=None,
        metavar="A:B",
        help="each house's camera height drawn from A..B metres (default: none, the shipped 0.3)",
    )
    rec = parser.add_argument_group("recovery views of a simulator dataset (a folder as --out)")
    rec.add_argument(
        "--recovery-for",
        default=None,
        metavar="DATASET",
        help="render off-path views with corrective labels for this dataset (training/recovery.py)",
    )
    rec.add_argument(
        "--recovery-per-window",
        type=float,
        default=0.25,
        help="recovery views per training window of the dataset (default: 0.25)",
    )
    from vtr.training import collect_robot

    collect_robot.add_arguments(parser)
    from vtr.training import bag_read

    bag_read.add_arguments(parser, "a dataset from teleoperated drives")


def run_cli(args: argparse.Namespace) -> int:
    import json

    if args.out is None:  # a file for one simulated house, a folder of shards for many houses or a robot
        many = args.houses or args.house_seeds
        args.out = "data/houses" if many else "data/robot" if args.sim is not None else "data/house.npz"
    if args.houses or args.house_seeds:
        from vtr.training.collect_houses import main_houses

        try:
            return main_houses(args)
        except ValueError as err:
            print(f"vtr collect: {err}", file=sys.stderr)
            return 2
    if args.recovery_for:
        from vtr.training.dataset import DatasetError
        from vtr.training.recovery import RecoveryConfig, render_recovery

        try:
            cfg_r = RecoveryConfig(per_window=args.recovery_per_window, seed=args.seed)
            summary_r = render_recovery(
                args.recovery_for, args.out, cfg_r, workers=args.workers, progress=not args.no_progress
            )
        except (ValueError, DatasetError) as err:
            print(f"vtr collect: {err}", file=sys.stderr)
            return 2
        print(json.dumps(summary_r, indent=2))
        return 0
    if args.sim is not None:  # a protocol robot instead of the in-process simulator
        from vtr.training import collect_robot

        return collect_robot.run_cli(args)
    if args.bag:  # teleoperated drives recorded in ROS bags
        from vtr.training import collect_bag

        return collect_bag.run_cli(args)

    if args.frames < MIN_FRAMES:  # a dataset nothing can be trained on: say so now, not at training time
        print(
            f"vtr collect: --frames {args.frames} is too few to train on: training holds an episode out for "
            f"validation and an episode lasts up to {CollectConfig.episode_max} frames; record at least "
            f"{MIN_FRAMES}",
            file=sys.stderr,
        )
        return 2
    cfg = CollectConfig(
        out=args.out,
        frames=args.frames,
        seed=args.seed,
        noise=args.noise,
        image_size=args.image_size,
        progress=not args.no_progress,
    )
    summary = run(cfg)
    print(json.dumps(summary, indent=2))
    return 0
