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
from typing import Any

import numpy as np


def stage_samples(rep: Any, steps: int, warmup: int) -> dict[str, np.ndarray]:
    """CPU us per step of each stage of ``studies.step_profile.STAGES`` over ``steps`` steps of ``rep``."""
    from studies.step_profile import STAGES, TOP_LEVEL, _owners

    clock = time.thread_time_ns
    owners = _owners(rep)
    per_step: dict[str, int] = {}

    def wrap(label: str, call: Any) -> Any:
        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = clock()
            try:
                return call(*args, **kwargs)
            finally:
                per_step[label] = per_step.get(label, 0) + clock() - t0

        return timed

    restore = []
    for label, owner, attr in STAGES:
        target = owners[owner]
        call = getattr(target, attr, None) if target is not None else None
        if call is None:
            continue
        restore.append((target, attr, target.__dict__.get(attr) if hasattr(target, "__dict__") else None))
        setattr(target, attr, wrap(label, call))
    samples: dict[str, list[int]] = {}
    try:
        for i in range(warmup + steps):
            per_step.clear()
            t0 = clock()
            rep.step()
            whole = clock() - t0
            if i < warmup:
                continue
            per_step["step"] = whole
            per_step["step.own"] = whole - sum(per_step.get(k, 0) for k in TOP_LEVEL)
            for k, v in per_step.items():
                samples.setdefault(k, []).append(v)
    finally:
        for target, attr, old in reversed(restore):
            if old is None:
                delattr(target, attr)
            else:
                setattr(target, attr, old)
    order = ["step", "step.own"] + [label for label, _, _ in STAGES]
    return {
        k: np.array(samples[k] + [0] * (steps - len(samples[k])), dtype=np.float64) / 1e3
        for k in dict.fromkeys(order)
        if k in samples
    }


def main(argv: list[str] | None = None) -> int:
    from vtr.benchmarks.step_bench import BenchStep, sample_taught

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="VelocityNet ONNX")
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--warmup", type=int, default=200)
    args = parser.parse_args(argv)
    current, route, poses = sample_taught(128, 128)
    rep = BenchStep(args.model, 1, current, route, match_light=True, poses=poses).repeater
    result = stage_samples(rep, args.steps, args.warmup)
    print(f"{'stage':<40}{'p50 us':>9}{'p99 us':>9}")
    for name, s in result.items():
        depth = name.count(".")
        p50, p99 = np.percentile(s, [50, 99])
        print(f"{'  ' * depth}{name:<{40 - 2 * depth}}{p50:9.1f}{p99:9.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
