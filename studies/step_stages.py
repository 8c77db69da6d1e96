"""`python -m studies.step_stages MODEL` (from the checkout's root): the taught step's stages with
p50 and p99 of the step thread's CPU time (``studies.step_profile`` prints medians only).

The step is ``vtr bench latency``'s ``whole_step_taught`` (the sample route with its taught poses: the
obstruction detector and the side estimate at work). Each stage is wrapped as ``studies.step_profile``
wraps it; a stage absent from a step counts 0 there (per step, not per call).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def main(argv: list[str] | None = None) -> int:
    from studies.step_profile import stage_samples
    from vtr.benchmarks.step_bench import BenchStep, sample_taught

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="VelocityNet ONNX")
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--warmup", type=int, default=200)
    args = parser.parse_args(argv)
    current, route, poses = sample_taught(128, 128)
    rep = BenchStep(args.model, 1, current, route, match_light=True, poses=poses).repeater
    result, _ = stage_samples(rep, args.steps, args.warmup, time.thread_time_ns)
    print(f"{'stage':<40}{'p50 us':>9}{'p99 us':>9}")
    for name, s in result.items():
        depth = name.count(".")
        p50, p99 = np.percentile(s, [50, 99])
        print(f"{'  ' * depth}{name:<{40 - 2 * depth}}{p50:9.1f}{p99:9.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
