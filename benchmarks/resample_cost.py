"""What mapping a camera's frame to the model's input costs (runtime/resample.py), beside one inference, in
one interleaved run.

    python -m vtr.benchmarks.resample_cost [--steps 300] [--model models/velocitynet.onnx]

Per camera size: the frame the runtime makes where the image enters (``CameraMapping.frame``: the centre crop
of the model's aspect, area-resampled to the model's size), for a 4:3 camera whose square centre sees the
model's field of view and for the 256x256 and 512x384 cameras that map by an integer factor; and, interleaved
with them, one ``OnnxPolicy.predict`` on the mapped frames. Frames are noise, a new one each step (the cost does
not depend on what they show). Single thread.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

from vtr.benchmarks.timing import stage_bench_main
from vtr.runtime.cliargs import opt

ROOT = Path(__file__).resolve().parents[1]
#: Camera sizes timed (W x H): the model's own (a pass-through), integer factors, and common 4:3 cameras.
SIZES = ((128, 128), (160, 120), (256, 256), (320, 240), (512, 384), (640, 480), (1280, 960))


@dataclass(frozen=True)
class ResampleBenchConfig:
    steps: int = opt(300, "timed steps (after 20 untimed)")
    model: str = opt(str(ROOT / "models" / "velocitynet.onnx"), "VelocityNet ONNX whose input frames map to")


def run(cfg: ResampleBenchConfig) -> dict[str, dict[str, float]]:
    import numpy as np

    from vtr.benchmarks.timing import time_interleaved
    from vtr.runtime.contracts import CameraSpec
    from vtr.runtime.hello import fit_camera
    from vtr.runtime.policy import OnnxPolicy

    policy = OnnxPolicy(cfg.model)
    meta = policy.meta
    rng = np.random.default_rng(0)
    fns = {}
    subgoal = rng.integers(0, 256, (meta.image_height, meta.image_width, 3), dtype=np.uint8)
    for w, h in SIZES:
        seen = meta.camera_fov_deg or 90.0
        side = min(w, h * meta.image_width / meta.image_height)
        fov = math.degrees(2 * math.atan(math.tan(math.radians(seen) / 2) * w / side))
        mapping = fit_camera(CameraSpec(w, h, fov, meta.camera_height_m), meta)
        frames = [rng.integers(0, 256, (h, w, 3), dtype=np.uint8) for _ in range(8)]
        for f in frames:
            f.flags.writeable = False  # as the decoder's np.frombuffer
        index = iter(range(10**9))
        fns[f"{w}x{h} -> {meta.image_width}x{meta.image_height}"] = lambda m=mapping, fr=frames, it=index: (
            m.frame(fr[next(it) % len(fr)])
        )
    mapped = [f.image for f in (fns[next(iter(fns))](),)]
    fns["inference (predict, fp32)"] = lambda: policy.predict(mapped[0], subgoal)
    return time_interleaved(fns, cfg.steps, 20)


def main(argv: list[str] | None = None) -> int:
    return stage_bench_main(
        argv, __doc__.splitlines()[0], ResampleBenchConfig, run, lambda c: f"{c.steps} steps, single thread"
    )


if __name__ == "__main__":
    sys.exit(main())
