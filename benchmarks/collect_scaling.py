"""Does `vtr collect --sim` slow down as its dataset grows? Frames/s in windows along one long collection.

    nice -n 19 python -m vtr.benchmarks.collect_scaling --frames 100000 --image-size 64 --out /tmp/scale
    nice -n 19 python -m vtr.benchmarks.collect_scaling --robot sim --frames 20000 --out /tmp/scale_sim

``--robot fake`` (default) is a robot that costs next to nothing per step (a synthetic image), so what is timed
is the recording and its checkpoints; ``--robot sim`` is the 2D simulator served over ZeroMQ in this process,
as `vtr collect --sim` meets it. Frames/s is reported for each window of ``--window`` frames; the verdict
compares the window ending at ``--frames`` with the one around 2,000 frames.
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
    """Wraps a robot: the wall time at every ``window``-th step."""

    def __init__(self, robot: Any, window: int) -> None:
        self.robot, self.window, self.marks = robot, window, [(0, time.perf_counter())]
        self.steps = 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.robot, name)

    def step(self, v: float, w: float, duration: float) -> Observation:
        obs = self.robot.step(v, w, duration)
        self.steps += 1
        if self.steps % self.window == 0:
            self.marks.append((self.steps, time.perf_counter()))
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


def _median_rate(rates: list[dict], lo: int, hi: int) -> float:
    return float(np.median([r["frames_per_s"] for r in rates if lo < r["frames"] <= hi]))


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
        {"frames": s1, "frames_per_s": round((s1 - s0) / (t1 - t0), 1)}
        for (s0, t0), (s1, t1) in zip(timed.marks, timed.marks[1:], strict=False)
    ]
    # medians over windows: one window of a fast robot is a fraction of a second, at the mercy of the page cache
    early = _median_rate(rates, 1000, 3000)  # frames 1,000-3,000
    late = _median_rate(rates, frames - 5 * window, frames)  # the last 5 windows
    result = {
        "robot": robot,
        "image_size": image_size,
        "save_every": save_every,
        "frames": frames,
        "windows": rates,
        "frames_per_s_near_2000": round(early, 1),
        "frames_per_s_at_end": round(late, 1),
        "ratio": round(late / early, 3),
    }
    # the cost of a checkpoint per frame it writes: the first 5 against the last 5 (not the final one)
    if len(checkpoints) > 11:
        per_frame = [(n, 1e6 * s / (b / (3 * image_size**2))) for n, s, b in checkpoints[:-1]]
        result["checkpoint_us_per_frame_first5"] = round(float(np.median([c[1] for c in per_frame[:5]])), 1)
        result["checkpoint_us_per_frame_last5"] = round(float(np.median([c[1] for c in per_frame[-5:]])), 1)
        result["checkpoints"] = len(checkpoints)
    return result


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=100_000)
    p.add_argument("--image-size", type=int, default=64)
    p.add_argument("--out", default="/tmp/collect_scaling")
    p.add_argument("--robot", choices=("fake", "sim"), default="fake")
    p.add_argument("--window", type=int, default=1000, help="frames per timed window")
    p.add_argument("--save-every", type=int, default=1000, help="frames between checkpoints")
    p.add_argument("--json", default=None, help="also write the result here")
    args = p.parse_args(argv)
    result = run(args.frames, args.image_size, args.out, args.robot, args.window, args.save_every)
    for r in result["windows"]:
        print(f"{r['frames']:>8} frames  {r['frames_per_s']:>9.1f} frames/s")
    print(json.dumps({k: v for k, v in result.items() if k != "windows"}))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
