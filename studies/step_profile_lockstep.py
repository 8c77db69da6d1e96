"""`python -m studies.step_profile_lockstep OLD_CHECKOUT [NEW_CHECKOUT] --model MODEL`: the real step of two
checkouts in lockstep, for an A/B on a shared, busy machine.

Each checkout runs in its own process (``PYTHONPATH`` set to it), stepping ``step_bench.BenchStep`` (the
light-matched step by default) on the same frames, one step when told; the two are told in turn (the order
swapped every step), so both see the machine as it is at that moment, and per step each reports the CPU
time its thread spent in the judgement and the policy (the benchmark's ``compute_cpu``), the wall time of the
compute, the CPU time of one inference alone right after, and of the judgement alone. Prints p50 / p99 of
each and the median of the paired differences (an A/A run, the same checkout twice, shows the noise floor).
Older checkouts need ``benchmarks/step_bench.py`` with ``compute_cpu_ms`` (session 2 on).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

#: The variants: BenchStep keyword arguments (the image comparison and light matching; ``taught``: the light
#: step on the route with its taught poses, the obstruction detector and the side estimate at work).
VARIANTS = ("light", "patch", "raw", "taught")


def worker(variant: str, model: str) -> None:
    """Step on each line read from stdin; write "compute_cpu compute_wall inference judge" (us) per step."""
    from vtr.benchmarks import step_bench
    from vtr.runtime.matching import MatchConfig
    from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL
    from vtr.runtime.preprocess import to_nchw

    BenchStep = step_bench.BenchStep
    # "taught" needs a checkout with step_bench.sample_taught (copy the file into an older one)
    if variant == "taught":
        current, route, poses = step_bench.sample_taught(128, 128)
        kwargs: dict[str, object] = {"match_light": True, "poses": poses}
    else:
        current, route = step_bench.sample_route(128, 128)
        kwargs = {"light": {"match_light": True}, "patch": {}, "raw": {"match": MatchConfig.paper()}}[variant]
    bench = BenchStep(model, 1, current, route, **kwargs)
    feeds = {INPUT_CURRENT: to_nchw(current), INPUT_SUBGOAL: to_nchw(route[0])}
    controller = bench.repeater.controller
    judge_ns = [0]
    judge = controller.judge

    def timed_judge(*args: object, **kw: object) -> object:
        t0 = time.thread_time_ns()
        try:
            return judge(*args, **kw)
        finally:
            judge_ns[0] = time.thread_time_ns() - t0

    controller.judge = timed_judge
    for _ in range(100):
        bench()
        bench.policy.infer(feeds)
    for _ in sys.stdin:
        bench()
        t0 = time.thread_time_ns()
        bench.policy.infer(feeds)
        inference = time.thread_time_ns() - t0
        cpu, wall = bench.compute_cpu_ms[-1] * 1e3, bench.compute_ms[-1] * 1e3
        sys.stdout.write(f"{cpu:.1f} {wall:.1f} {inference / 1e3:.1f} {judge_ns[0] / 1e3:.1f}\n")
        sys.stdout.flush()


def lockstep(roots: dict[str, str], variant: str, model: str, steps: int) -> dict[str, np.ndarray]:
    """(steps, 4) samples per checkout: compute CPU, compute wall, inference CPU, judgement CPU (us)."""
    procs = {
        name: subprocess.Popen(
            [sys.executable, "-m", "studies.step_profile_lockstep", "--worker", variant, "--model", model],
            cwd=root,
            env={**os.environ, "PYTHONPATH": root},
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        for name, root in roots.items()
    }
    samples: dict[str, list[list[float]]] = {name: [] for name in procs}
    names = list(procs)
    try:
        for i in range(steps):
            for name in names if i % 2 else names[::-1]:
                proc = procs[name]
                assert proc.stdin is not None and proc.stdout is not None
                proc.stdin.write("\n")
                proc.stdin.flush()
                samples[name].append([float(x) for x in proc.stdout.readline().split()])
    finally:
        for proc in procs.values():
            if proc.stdin is not None:
                proc.stdin.close()
            proc.wait()
    return {name: np.array(s) for name, s in samples.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", nargs="?", help="checkout A (e.g. from `git archive REV | tar -x -C DIR`)")
    parser.add_argument("new", nargs="?", default=".", help="checkout B (default: this one)")
    parser.add_argument(
        "--model", default="models/velocitynet.onnx", help="VelocityNet ONNX (relative: in each)"
    )
    parser.add_argument("--variant", choices=VARIANTS, default="light", help="the step (default: light)")
    parser.add_argument("--steps", type=int, default=1500, help="steps per checkout (default: 1500)")
    parser.add_argument("--worker", choices=VARIANTS, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        worker(args.worker, args.model)
        return 0
    if not args.old:
        parser.error("name the checkout to compare with")
    roots = {"A": str(Path(args.old).resolve()), "B": str(Path(args.new).resolve())}
    data = lockstep(roots, args.variant, args.model, args.steps)
    print(
        f"{args.variant} step, {args.steps} steps each, load average {os.getloadavg()[0]:.2f}; us, p50 / p99"
    )
    for name, a in data.items():
        cpu, wall, inference, judge = a.T

        def q(x: np.ndarray) -> str:
            return f"{np.percentile(x, 50):6.0f} / {np.percentile(x, 99):6.0f}"

        ratio = np.percentile(cpu, 50) / np.percentile(inference, 50)
        print(
            f"{name} {roots[name]}\n  compute cpu {q(cpu)}  compute wall {q(wall)}  inference cpu "
            f"{q(inference)}  judgement cpu {q(judge)}  compute/inference (cpu p50) {ratio:.2f}x"
        )
    diff = data["A"] - data["B"]
    print(
        f"paired A - B, median: compute cpu {np.median(diff[:, 0]):.0f} us, judgement cpu "
        f"{np.median(diff[:, 3]):.0f} us, inference cpu {np.median(diff[:, 2]):.0f} us"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
