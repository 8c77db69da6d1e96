"""What a range scan costs per control step, beside the camera render, in one interleaved run.

    python -m vtr.benchmarks.scan_cost [--steps 400] [--beams 181]

Per step, at a free pose of the paper house (a box on the living-room floor): the simulator's camera render and
its scan (``Simulator.scan``: rays, then the typed Scan) and the server's image reply encoded with and without
the scan, interleaved; then, interleaved apart, the client's decode with and without it and the safety layer's
``limit_twist`` on it. Single thread.
"""

from __future__ import annotations

import itertools
import sys
from dataclasses import dataclass

from vtr.benchmarks.timing import stage_bench_main
from vtr.runtime.cliargs import opt


@dataclass(frozen=True)
class ScanBenchConfig:
    steps: int = opt(400, "timed steps (after 20 untimed)")
    beams: int = opt(181, "beams of the scanner (over 270 deg)")
    house: str = opt("house", "map to benchmark")


def run(cfg: ScanBenchConfig) -> dict[str, dict[str, float]]:
    import numpy as np

    from vtr.benchmarks.timing import time_interleaved
    from vtr.runtime import protocol
    from vtr.runtime.safety import limit_twist
    from vtr.sim2d import SimConfig, Simulator
    from vtr.sim2d.config import RangefinderConfig

    sim = Simulator(
        SimConfig(
            house=cfg.house, changes=("obstacle:4.2,3.0=0.25",), rangefinder=RangefinderConfig(cfg.beams)
        )
    )
    house, rng = sim.house, np.random.default_rng(0)
    x0, y0, x1, y1 = house.bounds
    poses = []
    while len(poses) < 64:
        x, y = rng.uniform(x0, x1), rng.uniform(y0, y1)
        if house.is_free(x, y, 0.2):
            poses.append((float(x), float(y), float(rng.uniform(-np.pi, np.pi))))
    spec = sim.rangefinder.spec
    image = sim.camera.render(*poses[0])
    scans = [sim.rangefinder.scan(*p) for p in poses]
    with_scan = [
        protocol.encode_image_reply("step", 1, "s", 1.0, image, p, False, s)
        for p, s in zip(poses, scans, strict=True)
    ]
    without = protocol.encode_image_reply("step", 1, "s", 1.0, image, poses[0])
    turn = itertools.cycle(range(len(poses)))
    i = 0

    def advance() -> None:
        nonlocal i
        i = next(turn)

    # the simulator's side (the server renders and scans), then the runtime's side (another process: its
    # small stages are not timed beside a render, whose 23 MB texture atlas would evict their caches)
    simulator = {
        "next pose": advance,
        "camera render": lambda: sim.camera.render(*poses[i]),
        "scan (rays + Scan)": lambda: sim.rangefinder.scan(*poses[i]),
        "encode reply, no scan": lambda: protocol.encode_image_reply("step", 1, "s", 1.0, image, poses[i]),
        "encode reply with scan": lambda: protocol.encode_image_reply(
            "step", 1, "s", 1.0, image, poses[i], False, scans[i]
        ),
    }
    runtime = {
        "next pose": advance,
        "decode reply, no scan": lambda: protocol.decode_reply(without),
        "decode reply with scan": lambda: protocol.decode_reply(with_scan[i], expect_scan=spec),
        "limit_twist": lambda: limit_twist(0.3, 0.1, scans[i]),
    }
    stages = time_interleaved(simulator, cfg.steps, 20) | time_interleaved(runtime, cfg.steps, 20)
    del stages["next pose"]
    return stages


def main(argv: list[str] | None = None) -> int:
    return stage_bench_main(
        argv, __doc__.splitlines()[0], ScanBenchConfig, run, lambda c: f"{c.beams} beams, {c.steps} steps"
    )


if __name__ == "__main__":
    sys.exit(main())
