"""Does `vtr collect --sim` slow down as its dataset grows? Frames/s in windows along one long collection.

    nice -n 19 python -m vtr.benchmarks.collect_scaling --frames 100000 --image-size 64 --out /tmp/scale
    nice -n 19 python -m vtr.benchmarks.collect_scaling --robot sim --frames 20000 --out /tmp/scale_sim
    nice -n 19 python -m vtr.benchmarks.collect_scaling --append-only --image-size 128 --out /tmp/scale_ckpt

``--robot fake`` (default) is a robot that costs next to nothing per step (a synthetic image), so what is timed
is the recording and its checkpoints; ``--robot sim`` is the 2D simulator served over ZeroMQ in this process,
as `vtr collect --sim` meets it. Frames/s is reported for each window of ``--window`` frames; the verdict
compares the last windows with those around 2,000 frames, per wall second and per CPU second of this process
(on a shared machine the wall rate follows the other jobs; the CPU rate much less). ``--append-only`` times the
checkpoint alone (training.shards.ShardAppender.append), first shards against last.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime.contracts import CameraSpec
from vtr.runtime.hello import Hello
from vtr.runtime.protocol import Limits
from vtr.runtime.robot import Observation


class FakeRobot:
    """A free plane: every step moves, nothing collides; images are cheap but not constant."""

    def __init__(self, size: int) -> None:
        self.size, self.t, self.pose = size, 0.0, (0.0, 0.0, 0.0)
        self.base = np.random.default_rng(0).integers(0, 255, (size, size, 3), dtype=np.uint8)

    def handshake(self) -> Hello:
        camera = CameraSpec(width=self.size, height=self.size, fov_deg=90.0, height_m=0.3)
        return Hello(
            "bench", 0.0, 1, camera, Limits(v_max=0.5, w_max=1.0), dt=0.1, mode="lockstep", map="plane"
        )

    def _obs(self) -> Observation:
        return Observation(np.roll(self.base, int(self.t * 10), axis=1), self.t, self.pose, False)

    def reset(self, pose: Any = None, seed: Any = None) -> Observation:
        return self._obs()

    def observe(self) -> Observation:
        return self._obs()

    def step(self, v: float, w: float, duration: float) -> Observation:
        self.t += duration
        return self._obs()

    def stop(self) -> None:
        pass


class Timed:
    """Wraps a robot: the wall time and this process's CPU time at every ``window``-th step."""

    def __init__(self, robot: Any, window: int) -> None:
        self.robot, self.window = robot, window
        self.marks = [(0, time.perf_counter(), time.process_time())]
        self.steps = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.robot, name)

    def step(self, v: float, w: float, duration: float) -> Observation:
        obs = self.robot.step(v, w, duration)
        self.steps += 1
        if self.steps % self.window == 0:
            self.marks.append((self.steps, time.perf_counter(), time.process_time()))
        return obs


def _time_checkpoints() -> list[tuple[int, float, int]]:
    """(frames before, seconds, bytes) of every shard append (training.shards.ShardAppender), when there is one."""
    from vtr.training import shards

    log: list[tuple[int, float, int]] = []
    appender = getattr(shards, "ShardAppender", None)
    if appender is None:  # the code before shards: a checkpoint rewrote the whole file
        return log
    original = appender.append

    def append(self: Any, arrays: dict, *args: Any, **kw: Any) -> None:
        t = time.perf_counter()
        original(self, arrays, *args, **kw)
        log.append((self.frames, time.perf_counter() - t, sum(a.nbytes for a in arrays.values())))

    appender.append = append
    return log


def _median_rate(rates: list[dict], lo: int, hi: int, key: str) -> float:
    return float(np.median([r[key] for r in rates if lo < r["frames"] <= hi]))


def run(frames: int, image_size: int, out: str, robot: str, window: int, save_every: int) -> dict[str, Any]:
    from vtr.training.collect_robot import RobotCollectConfig, collect

    checkpoints = _time_checkpoints()

    path = Path(out)
    if path.is_dir():
        shutil.rmtree(path)
    elif path.exists():
        path.unlink()
    cfg = RobotCollectConfig(
        sim="tcp://127.0.0.1:9", out=out, frames=frames, save_every=save_every, progress=False
    )
    if robot == "fake":
        timed = Timed(FakeRobot(image_size), window)
        collect(cfg, timed)
    else:
        from vtr.runtime.client import SimClient
        from vtr.sim2d import CameraConfig, SimConfig, Simulator
        from vtr.sim2d.server_launch import ServerThread

        sim = Simulator(SimConfig(camera=CameraConfig(width=image_size, height=image_size)))
        sim.reset()
        with ServerThread(sim) as server, SimClient(server.endpoint, 2.0, 3) as client:
            timed = Timed(client, window)
            collect(cfg, timed)
    rates = [
        {
            "frames": s1,
            "frames_per_s": round((s1 - s0) / (t1 - t0), 1),
            "frames_per_cpu_s": round((s1 - s0) / max(c1 - c0, 1e-6), 1),
        }
        for (s0, t0, c0), (s1, t1, c1) in zip(timed.marks, timed.marks[1:], strict=False)
    ]
    # Medians over windows: a window of a fast robot is a fraction of a second, at the mercy of the page cache.
    # Frames per CPU second (this process: robot, recording, checkpoints) do not depend on what else the
    # machine runs; frames per wall second do.
    result: dict[str, Any] = {
        "robot": robot,
        "image_size": image_size,
        "save_every": save_every,
        "frames": frames,
        "windows": rates,
    }
    for key in ("frames_per_s", "frames_per_cpu_s"):
        early = _median_rate(rates, 1000, 3000, key)  # frames 1,000-3,000
        late = _median_rate(rates, frames - 5 * window, frames, key)  # the last 5 windows
        result[key] = {
            "near_2000": round(early, 1),
            "at_end": round(late, 1),
            "ratio": round(late / early, 3),
        }
    # the cost of a checkpoint per frame it writes: the first 5 against the last 5 (not the final one)
    if len(checkpoints) > 11:
        per_frame = [(n, 1e6 * s / (b / (3 * image_size**2))) for n, s, b in checkpoints[:-1]]
        result["checkpoint_us_per_frame_first5"] = round(float(np.median([c[1] for c in per_frame[:5]])), 1)
        result["checkpoint_us_per_frame_last5"] = round(float(np.median([c[1] for c in per_frame[-5:]])), 1)
        result["checkpoints"] = len(checkpoints)
    return result


def append_only(frames: int, image_size: int, out: str, shard: int) -> dict[str, Any]:
    """The checkpoint alone: ShardAppender.append of ``shard``-frame shards until ``frames``, each timed."""
    from vtr.training.shards import ShardAppender

    shutil.rmtree(out, ignore_errors=True)
    store, rng = ShardAppender(out), np.random.default_rng(0)
    arrays = {
        "images": rng.integers(0, 255, (shard, image_size, image_size, 3), dtype=np.uint8),
        "commands": np.zeros((shard, 2), np.float32),
        "poses": np.zeros((shard, 3), np.float32),
        "episodes": np.repeat(np.arange(10), -(-shard // 10))[:shard].astype(np.int32),
    }
    rows = []
    while store.frames < frames:
        t, c = time.perf_counter(), time.process_time()
        store.append(arrays, house="bench", meta={"source": "bench"}, dt=0.1)
        rows.append((store.frames, 1000 * (time.perf_counter() - t), 1000 * (time.process_time() - c)))
    shutil.rmtree(out, ignore_errors=True)
    k = max(1, len(rows) // 10)

    def at(part: list) -> dict[str, float]:
        return {
            "frames": part[-1][0],
            "wall_ms": round(float(np.median([r[1] for r in part])), 1),
            "cpu_ms": round(float(np.median([r[2] for r in part])), 1),
        }

    return {"image_size": image_size, "shard_frames": shard, "first": at(rows[:k]), "last": at(rows[-k:])}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=100_000)
    p.add_argument("--image-size", type=int, default=64)
    p.add_argument("--out", default="/tmp/collect_scaling")
    p.add_argument("--robot", choices=("fake", "sim"), default="fake")
    p.add_argument("--window", type=int, default=1000, help="frames per timed window")
    p.add_argument("--save-every", type=int, default=1000, help="frames between checkpoints")
    p.add_argument("--json", default=None, help="also write the result here")
    p.add_argument(
        "--append-only",
        action="store_true",
        help="time the checkpoint alone: appending --save-every-frame shards up to --frames",
    )
    args = p.parse_args(argv)
    if args.append_only:
        print(json.dumps(append_only(args.frames, args.image_size, args.out, args.save_every)))
        return 0
    result = run(args.frames, args.image_size, args.out, args.robot, args.window, args.save_every)
    for r in result["windows"]:
        print(
            f"{r['frames']:>8} frames  {r['frames_per_s']:>9.1f} frames/s  {r['frames_per_cpu_s']:>9.1f} per CPU s"
        )
    print(json.dumps({k: v for k, v in result.items() if k != "windows"}))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
