"""`vtr collect --sim ADDR`: record a training dataset from any robot or simulator that serves the protocol.

    vtr collect --sim tcp://127.0.0.1:5555 --out data/mybuilding --frames 7024

The dataset is a folder of shards (training/shards.py, as `vtr collect --houses` writes), read by `vtr train`
like any dataset. The robot's map is unknown, so the
:class:`ExplorationDriver` keeps it safe with what the protocol gives: on ``collided`` the pair is cut (a collided
step did not follow its command), the robot backs off and turns away by 90-180 degrees. Commands mix what repeat
meets: turns in place both ways, creeping, straight runs, fast arcs, reverse and stops, each held for a few frames,
within the robot's announced limits capped at the model's (0.5 m/s, 1.0 rad/s). Episodes are 60-200 frames; the
robot is reset between episodes only with ``--reset-every`` and only when it accepts ``reset`` (otherwise it
drives on, continuously), and after repeated collisions (stuck) when it can.

``--around ROUTE.npz ...`` records where the routes will be repeated: every episode then starts from a reset to a
pose along those taught routes (yaw turned by up to +-35 degrees), so the data covers their rooms however far
they lie from the robot's start pose. It needs a robot that accepts ``reset`` with a pose (a simulator; on a
real robot drive it there, or record a teleoperated bag).

Resumable: an existing ``--out`` is extended (new episodes appended) until it holds ``--frames`` frames. Every
``--save-every`` frames, at the next episode's end, and on Ctrl-C, the frames since the last checkpoint are
appended as one shard (training/robot_recording.py): a checkpoint writes only them, never the frames before, and
a crash loses at most the shard being written.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from vtr.runtime import protocol
from vtr.runtime.address import check_endpoint
from vtr.runtime.cliargs import add_config_arguments, config_from_args, opt
from vtr.runtime.contracts import CONTROL_DT
from vtr.runtime.hello import Hello
from vtr.training.dataset import DatasetError
from vtr.training.robot_recording import Recording, check_out, check_resumable, load_existing

# (kind, probability): the driving mix repeat meets
COMMAND_MIX = (
    ("turn", 0.25),
    ("creep", 0.15),
    ("straight", 0.2),
    ("arc", 0.3),
    ("reverse", 0.07),
    ("stop", 0.03),
)


@dataclass
class RobotCollectConfig:
    """How `vtr collect --sim` drives a protocol robot."""

    sim: str = opt(None, "record from this robot/simulator endpoint instead of in-process", metavar="ADDR")
    out: str = "data/robot"  # dataset folder (shards), extended when it exists
    frames: int = 7024  # frames the dataset holds when done
    seed: int = 0  # command choice
    dt: float = CONTROL_DT  # s per command (the repeat's control step)
    episode_min: int = 60  # frames per episode, drawn uniformly
    episode_max: int = 200
    segment_min: int = 3  # a command is held this many frames
    segment_max: int = 14
    backoff_steps: int = 4  # reverse steps after a collision
    reset_every: int = opt(0, "--sim: reset every k episodes when the robot can; 0: only when stuck")
    save_every: int = opt(1000, "--sim: frames between checkpoints (a new shard at the next episode's end)")
    timeout_s: float = opt(2.0, "--sim: seconds to wait for each reply", flag="--timeout")
    retries: int = opt(3, "--sim: tries per request (hello, observe, stop; never a motion command)")
    around: tuple[str, ...] = opt(
        (),
        "--sim: taught routes (.npz): each episode starts at a pose along them (reset with a pose)",
        metavar="ROUTE",
    )
    progress: bool = True

    def __post_init__(self) -> None:
        check_endpoint(self.sim)
        check_out(self.out)
        for name in (
            "frames",
            "dt",
            "episode_min",
            "segment_min",
            "backoff_steps",
            "save_every",
            "timeout_s",
        ):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if self.episode_max < self.episode_min or self.segment_max < self.segment_min:
            raise ValueError("episode_max/segment_max must be >= episode_min/segment_min")
        if self.reset_every < 0:
            raise ValueError(f"reset_every must be >= 0, got {self.reset_every}")


#: How far an episode start turns from the taught heading at a pose along an --around route, rad.
AROUND_YAW_JITTER = math.radians(35.0)


def route_start_poses(paths: tuple[str, ...]) -> np.ndarray | None:
    """Every known pose (x, y, yaw) of the taught routes at ``paths``, or None without routes."""
    if not paths:
        return None
    from vtr.runtime.route import Route

    poses = np.concatenate([Route.load(p).poses for p in paths])
    poses = poses[np.isfinite(poses).all(axis=1)]
    if len(poses) == 0:
        raise ValueError(f"--around: no known poses in {', '.join(paths)} (routes taught without poses)")
    return poses


def _start_pose(rng: np.random.Generator, starts: np.ndarray) -> tuple[float, float, float]:
    x, y, yaw = starts[int(rng.integers(len(starts)))]
    yaw = (yaw + rng.uniform(-AROUND_YAW_JITTER, AROUND_YAW_JITTER) + math.pi) % (2 * math.pi) - math.pi
    return float(x), float(y), float(yaw)


class ExplorationDriver:
    """Picks the next (kind, v, w) from the command mix; after a collision, backs off and turns away."""

    def __init__(self, rng: np.random.Generator, v_max: float, w_max: float, cfg: RobotCollectConfig) -> None:
        self.rng, self.v_max, self.w_max, self.cfg = rng, v_max, w_max, cfg
        self.plan: list[tuple[str, float, float]] = []  # commands queued ahead (a held segment or an escape)
        kinds, probs = zip(*COMMAND_MIX, strict=True)
        self._kinds, self._probs = kinds, np.array(probs) / sum(probs)

    def sample(self) -> tuple[str, float, float]:
        r, vm, wm = self.rng, self.v_max, self.w_max
        kind = str(r.choice(self._kinds, p=self._probs))
        sign = 1.0 if r.random() < 0.5 else -1.0
        v, w = {
            "turn": (0.0, sign * r.uniform(0.2, 1.0) * wm),
            "creep": (r.uniform(0.05, 0.2) * vm, sign * r.uniform(0.0, 0.2) * wm),
            "straight": (r.uniform(0.3, 1.0) * vm, 0.0),
            "arc": (r.uniform(0.5, 1.0) * vm, sign * r.uniform(0.3, 1.0) * wm),
            "reverse": (-r.uniform(0.1, 0.5) * vm, sign * r.uniform(0.0, 0.3) * wm),
            "stop": (0.0, 0.0),
        }[kind]
        return kind, float(v), float(w)

    def next(self) -> tuple[str, float, float]:
        if not self.plan:
            command = self.sample()
            self.plan = [command] * int(self.rng.integers(self.cfg.segment_min, self.cfg.segment_max + 1))
        return self.plan.pop(0)

    def collided(self, turn_rad: float | None = None) -> None:
        """Back off, then turn away by 90-180 degrees (or ``turn_rad``) in a random direction."""
        turn = turn_rad if turn_rad is not None else float(self.rng.uniform(math.pi / 2, math.pi))
        w = (1.0 if self.rng.random() < 0.5 else -1.0) * 0.8 * self.w_max
        back = [("escape", -0.4 * self.v_max, 0.0)] * self.cfg.backoff_steps
        self.plan = back + [("escape", 0.0, w)] * max(1, round(turn / (abs(w) * self.cfg.dt)))


def collect(cfg: RobotCollectConfig, client: Any, log: Any = sys.stdout) -> dict[str, Any]:
    """Drive ``client`` (a SimClient, or any Robot with handshake/reset) and write ``cfg.out``; returns a summary."""
    hello: Hello = client.handshake()  # validated (runtime.hello); the client then holds steps to its limits
    camera = dataclasses.asdict(hello.camera)
    # the robot's limits capped at the model's: VelocityNet cannot output more, so such pairs would be useless
    v_max, w_max = min(hello.limits.v_max, protocol.V_MAX), min(hello.limits.w_max, protocol.W_MAX)
    rec = load_existing(cfg.out)
    check_resumable(rec, camera, cfg.dt, cfg.out)
    start_frames = rec.frames
    if start_frames >= cfg.frames:
        print(
            f"collect: {cfg.out} already holds {start_frames} frames (>= {cfg.frames}); nothing to do",
            file=log,
        )
        return {"out": cfg.out, "frames": start_frames, "added": 0}
    rec.meta.update(
        source="vtr collect --sim",
        dt=cfg.dt,
        seed=cfg.seed,
        camera=camera,
        map=hello.map or hello.robot or "robot",
        limits={"v_max": v_max, "w_max": w_max},
    )
    rng = np.random.default_rng([cfg.seed, start_frames])  # a resumed run does not replay the same commands
    driver = ExplorationDriver(rng, v_max, w_max, cfg)
    starts = route_start_poses(cfg.around)
    if starts is not None:
        rec.meta["around"] = list(cfg.around)
        obs, can_reset = client.reset(pose=_start_pose(rng, starts), seed=cfg.seed), True  # refused: one line
    else:
        try:
            obs, can_reset = client.reset(seed=cfg.seed), True
        except Exception as exc:  # a robot that cannot be reset drives continuously from where it stands
            print(f"collect: no reset ({exc}); driving continuously from here", file=log)
            obs, can_reset = client.observe(), False
    h, w = obs.image.shape[:2]
    if h != w:  # found now, not after an hour of driving when the dataset is written
        raise DatasetError(
            f"the robot's images are {w}x{h}; datasets hold square images: crop them in the bridge"
        )
    episode_len = int(rng.integers(cfg.episode_min, cfg.episode_max + 1))
    in_episode, recent_hits, t0, last_print = 0, [], time.monotonic(), 0.0
    episodes_done = 0
    try:
        while rec.frames < cfg.frames:
            rec.add(obs)
            in_episode += 1
            if rec.frames >= cfg.frames:
                break
            kind, v, w = driver.next()
            try:
                new = client.step(v, w, cfg.dt)
            except protocol.BadFrameError:  # the frame after this one is unknown: cut the episode here
                rec.count("bad_frames")
                new, kind = client.observe(), "cut"
            step = rec.frames
            if new.collided:
                rec.count("collisions")
                recent_hits = [s for s in recent_hits if step - s < 40] + [step]
                driver.collided(math.pi if len(recent_hits) >= 3 else None)
            ending = new.collided or kind == "cut" or in_episode >= episode_len
            if ending:
                rec.end_episode()
                episodes_done += 1
                in_episode, episode_len = 0, int(rng.integers(cfg.episode_min, cfg.episode_max + 1))
                stuck = len(recent_hits) >= 3
                due = cfg.reset_every and episodes_done % cfg.reset_every == 0
                if starts is not None:  # every episode starts somewhere along the routes
                    pose = _start_pose(rng, starts)
                    new, recent_hits = client.reset(pose=pose, seed=cfg.seed + rec.episode), []
                    rec.count("resets")
                elif can_reset and (stuck or due):
                    new, recent_hits = client.reset(seed=cfg.seed + rec.episode), []
                    rec.count("resets")
                if len(rec.images) >= cfg.save_every:  # a checkpoint: these episodes become a shard
                    rec.save(cfg.dt)
            else:
                rec.commands[-1] = (v, w)
                rec.count(kind)
            obs = new
            if cfg.progress and time.monotonic() - last_print > 5.0:
                last_print = time.monotonic()
                _progress(rec, start_frames, cfg.frames, time.monotonic() - t0, log)
    finally:
        try:
            client.stop()
        finally:
            rec.save(cfg.dt)  # the last frame ends its episode
    elapsed = time.monotonic() - t0
    if cfg.progress:
        _progress(rec, start_frames, cfg.frames, elapsed, log)
    return {
        "out": cfg.out,
        "frames": rec.frames,
        "added": rec.frames - start_frames,
        "episodes": rec.n_episodes,
        "seconds": round(elapsed, 1),
        "counts": dict(sorted(rec.counts.items())),
        "reset": can_reset,
    }


def _progress(rec: Recording, start: int, target: int, elapsed: float, log: Any) -> None:
    added = rec.frames - start
    rate = added / elapsed if elapsed > 0 else 0.0
    eta = (target - rec.frames) / rate if rate > 0 else float("inf")
    print(
        f"collect: {rec.frames}/{target} frames, {rec.n_episodes} episodes, "
        f"{rec.counts.get('collisions', 0)} collisions, {rate:.0f} frames/s, eta {eta:.0f} s",
        file=log,
        flush=True,
    )


def run(cfg: RobotCollectConfig) -> dict[str, Any]:
    from vtr.runtime.client import SimClient

    with SimClient(cfg.sim, cfg.timeout_s, cfg.retries) as client:
        return collect(cfg, client)


def add_arguments(parser: Any) -> None:
    """`vtr collect --sim ...` options (added to `vtr collect`'s parser)."""
    add_config_arguments(parser.add_argument_group("from a protocol robot (--sim)"), RobotCollectConfig)


def run_cli(args: Any) -> int:
    import json

    from vtr.runtime.robot import RobotError

    try:
        common = {"out": args.out, "frames": args.frames, "seed": args.seed, "progress": not args.no_progress}
        cfg = config_from_args(RobotCollectConfig, args, **common)
        summary = run(cfg)
    except (ValueError, OSError, RobotError) as exc:  # DatasetError is a ValueError
        print(f"vtr collect: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(summary, indent=2))
    return 0
