"""`vtr collect`: drive the simulated robot through the house and record a training dataset.

    vtr collect --out data/house.npz --frames 7024 --seed 0 [--noise 0.05]

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
from typing import Any

import numpy as np

from vtr.training.config import CollectConfig

_KINDS = ("translate", "rotate", "combined", "stop")
_KIND_P = (0.3, 0.3, 0.35, 0.05)


def arc_points(x: float, y: float, yaw: float, v: float, w: float, horizon: float, samples: int = 4) -> list:
    """Unicycle positions along (v, w) at ``samples`` times in (0, horizon]."""
    out = []
    for k in range(1, samples + 1):
        t = horizon * k / samples
        if abs(w) < 1e-6:
            out.append((x + v * t * math.cos(yaw), y + v * t * math.sin(yaw)))
        else:
            r = v / w
            out.append(
                (
                    x + r * (math.sin(yaw + w * t) - math.sin(yaw)),
                    y - r * (math.cos(yaw + w * t) - math.cos(yaw)),
                )
            )
    return out


def sample_command(rng: np.random.Generator, cfg: CollectConfig) -> tuple[str, float, float]:
    kind = str(rng.choice(_KINDS, p=_KIND_P))
    sign_v = -1.0 if rng.random() < cfg.reverse_fraction else 1.0
    sign_w = -1.0 if rng.random() < 0.5 else 1.0
    v = sign_v * float(rng.uniform(0.05, 1.0)) * cfg.v_max
    w = sign_w * float(rng.uniform(0.05, 1.0)) * cfg.w_max
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


def run(cfg: CollectConfig) -> dict[str, Any]:
    """Drive, record and write the dataset atomically; returns a summary."""
    from tqdm import tqdm

    from vtr.sim2d import CameraConfig, Pose, SimConfig, Simulator
    from vtr.training.dataset import FORMAT_VERSION, FrameData, save_dataset

    sim_cfg = SimConfig(camera=CameraConfig(width=cfg.image_size, height=cfg.image_size), noise=cfg.noise)
    sim = Simulator(sim_cfg)
    house = sim.house
    min_radius = max(cfg.robot_radius, sim_cfg.robot_radius)
    radius = min_radius
    rng = np.random.default_rng(cfg.seed)
    n = cfg.frames
    images = np.zeros((n, cfg.image_size, cfg.image_size, 3), np.uint8)
    commands = np.zeros((n, 2), np.float32)
    poses = np.zeros((n, 3), np.float32)
    episodes = np.zeros(n, np.int32)
    kinds = dict.fromkeys(_KINDS, 0)
    kinds["escape"] = 0
    rooms: dict[str, int] = {}
    collisions = 0
    t, ep = 0, 0
    bar = tqdm(total=n, desc="collect", disable=not cfg.progress, dynamic_ncols=True)

    def safe(p: Any, v: float, w: float) -> bool:
        pts = arc_points(p.x, p.y, p.yaw, v, w, cfg.dt + cfg.lookahead)
        return all(house.is_free(px, py, radius) for px, py in pts)

    image = None
    fresh_start = True
    while t < n:
        if fresh_start:
            radius = float(rng.uniform(min_radius, max(min_radius, cfg.far_clearance)))
            room = house.rooms[ep % len(house.rooms)]
            image = sim.reset(
                pose=Pose(*sample_pose(house, room, rng, radius)), seed=cfg.seed * 1_000_003 + ep
            )
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
            images[t], poses[t], episodes[t] = image, pose, ep
            rooms[house.room_at(pose.x, pose.y) or "?"] = (
                rooms.get(house.room_at(pose.x, pose.y) or "?", 0) + 1
            )
            t += 1
            bar.update(1)
            if k == length - 1 or t == n:
                break  # last frame of the episode: its command stays zero
            commands[t - 1] = (v, w)
            kinds[kind] += 1
            image = sim.step(v, w, cfg.dt)
            if sim.collided:
                # The step did not follow the command: cut the pair, start a new episode from here.
                commands[t - 1] = 0.0
                collisions += 1
                fresh_start = False
                break
        ep += 1
    bar.close()
    meta = {
        "source": "vtr collect",
        "format_version": FORMAT_VERSION,
        "dt": cfg.dt,
        "seed": cfg.seed,
        "noise": cfg.noise,
        "map": house.name,
        "camera": sim.info().get("camera", {}),
        "robot_radius": sim_cfg.robot_radius,
        "collect_config": {k: v for k, v in vars(cfg).items() if k != "progress"},
    }
    save_dataset(cfg.out, FrameData(images, commands, poses, episodes, meta))
    summary = {
        "out": cfg.out,
        "frames": n,
        "episodes": ep,
        "collisions": collisions,
        "commands": kinds,
        "rooms": rooms,
    }
    return summary


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="data/house.npz", help="dataset file (.npz), written atomically")
    parser.add_argument("--frames", type=int, default=7024, help="frames to record (paper: 7024)")
    parser.add_argument(
        "--seed", type=int, default=0, help="seed for start poses, commands and actuation noise"
    )
    parser.add_argument(
        "--noise",
        nargs="?",
        type=float,
        const=0.05,
        default=0.0,
        help="actuation noise level (SimConfig.noise); --noise alone means 0.05",
    )
    parser.add_argument("--image-size", type=int, default=128, help="camera width = height (default 128)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    from vtr.training import collect_robot

    collect_robot.add_arguments(parser)
    from vtr.runtime import bag_read

    bag_read.add_arguments(parser, "a dataset from teleoperated drives")


def run_cli(args: argparse.Namespace) -> int:
    import json

    if args.sim is not None:  # a protocol robot instead of the in-process simulator
        from vtr.training import collect_robot

        return collect_robot.run_cli(args)
    if args.bag:  # teleoperated drives recorded in ROS bags
        from vtr.training import collect_bag

        return collect_bag.run_cli(args)

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
