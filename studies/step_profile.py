"""`python -m studies.step_profile MODEL` (from the checkout's root): where one real ``Repeater.step``
spends its time, stage by stage (issue 11's step overhead).

Steps the light-matched, patch-matched or raw-error repeater of ``step_bench_ab`` (the route from
``step_bench.sample_route``, or ``--route ROUTE.npz``) and wraps each call below in a timer, nested as
the step nests them; prints the median of each (microseconds per step, a call made twice in a step
counted as the sum) and the step's own share (the whole step minus its four top-level calls: the
Repeater's and the controller's Python). Each wrapper adds about 0.3-1 us to its own figure and to
every figure above it, so the whole step here is slower than ``vtr bench latency``'s; the stages tell
where time goes, the ratio is `vtr bench latency`'s. ``--cprofile N`` prints the top N functions of
cProfile over the same steps instead (its overhead is larger and uneven: read it for call counts).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from vtr.benchmarks.step_bench import progress_afresh

#: (label, owner key, attribute): wrapped in this order; ``owner key`` names an object or a module.
STAGES: tuple[tuple[str, str, str], ...] = (
    ("link.step", "robot", "step"),
    ("link.stop", "robot", "stop"),
    ("link.decode_reply", "protocol", "decode_reply"),
    ("link.encode_request", "protocol", "encode_request"),
    ("judge", "controller", "judge"),
    ("judge.features", "matcher", "features"),
    ("judge.features.planar_levels", "frame", "planar"),  # once per frame (Frame.levels), wherever first
    ("judge.features.pool", "matching", "pool"),  # once per frame (pooled_sums), wherever first
    ("judge.features.tiles", "matcher", "_tiles"),
    ("judge.features.normalise", "matcher", "_centre"),  # the tile moments (Matcher.moments), once per frame
    ("judge.distance", "matcher", "distance"),
    ("judge.localise", "localiser", "update"),
    ("judge.localise.distances", "matcher", "distances"),
    ("judge.obstruction", "obstruction", "update"),
    ("judge.obstruction.pool", "floor", "pool"),
    ("judge.obstruction.features", "floor", "features"),
    ("judge.side", "side", "estimate"),  # the floor's side offset: only where the robot drives forward
    ("commanded", "localiser", "predict"),  # the localiser's motion update, after the step's command
    ("predict", "policy", "predict"),
    ("predict.light_match", "light", "matched_planar"),
    ("predict.light_match.ramp", "light", "_ramp"),
    ("predict.light_match.statistics", "light", "_stats_in_place"),
    ("predict.preprocess", "policy_module", "input_into"),
    ("predict.standardise", "preprocess", "normalise"),
    ("predict.inference", "onnx", "_run"),  # the network as predict runs it (IOBinding)
    ("predict.inference", "onnx", "infer"),  # the same in checkouts before IOBinding (predict called infer)
    ("predict.postprocess", "onnx", "postprocess"),
)
TOP_LEVEL = ("link.step", "link.stop", "judge", "predict", "commanded")


def _owners(rep: Any) -> dict[str, Any]:
    from vtr.runtime import frame, light, matching, policy, preprocess, protocol

    onnx = getattr(rep.policy, "policy", rep.policy)
    return {
        "robot": rep.robot,
        "protocol": protocol,
        "controller": rep.controller,
        "matcher": rep.controller.matcher,
        "localiser": getattr(rep.controller, "localiser", None),
        "obstruction": getattr(rep.controller, "obstruction", None),
        "floor": getattr(getattr(rep.controller, "obstruction", None), "floor", None),
        "side": getattr(rep.controller, "side", None),
        "matching": matching,
        "frame": frame,
        "preprocess": preprocess,
        "policy": rep.policy,
        "light": light,
        "policy_module": policy,
        "onnx": onnx,
    }


def stage_samples(
    rep: Any, steps: int, warmup: int, clock: Callable[[], int] = time.perf_counter_ns
) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """Us per step of each stage (and of the whole step) over ``steps`` steps of ``rep``, in ``STAGES``'
    order, and the calls each stage made over them; ``clock``: wall time, or ``time.thread_time_ns`` for the
    CPU time of the step's thread (what a busy machine's waits for a core leave out)."""
    owners = _owners(rep)
    per_step: dict[str, int] = {}
    calls: dict[str, int] = {}
    counting = 0  # 1 once the warm-up is over

    def wrap(label: str, call: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = clock()
            try:
                return call(*args, **kwargs)
            finally:
                per_step[label] = per_step.get(label, 0) + clock() - t0
                calls[label] = calls.get(label, 0) + counting

        return timed

    restore = []
    for label, owner, attr in STAGES:
        target = owners[owner]
        call = getattr(target, attr, None) if target is not None else None
        if call is None:  # e.g. no light matching in this variant
            continue
        restore.append((target, attr, target.__dict__.get(attr) if hasattr(target, "__dict__") else None))
        setattr(target, attr, wrap(label, call))
    samples: dict[str, list[int]] = {}
    try:
        for i in range(warmup + steps):
            per_step.clear()
            counting = int(i >= warmup)
            progress_afresh(rep)
            t0 = clock()
            record = rep.step()
            whole = clock() - t0
            if not record.commanded:
                raise RuntimeError(f"the repeat ended ({record.status})")
            if i < warmup:
                continue
            per_step["step"] = whole
            per_step["step.own"] = whole - sum(per_step.get(k, 0) for k in TOP_LEVEL)
            for k, v in per_step.items():
                samples.setdefault(k, []).append(v)
    finally:
        for target, attr, old in reversed(restore):
            if old is None:
                delattr(target, attr)  # an instance attribute shadowed the class's method
            else:
                setattr(target, attr, old)
    order = ["step", "step.own"] + [label for label, _, _ in STAGES]
    # a stage absent from some steps counts 0 there: the figures are per step, not per call
    per_stage = {
        k: np.array(samples[k] + [0] * (steps - len(samples[k])), dtype=np.float64) / 1e3
        for k in dict.fromkeys(order)
        if k in samples
    }
    return per_stage, calls


def profile_stages(
    rep: Any, steps: int, warmup: int, clock: Callable[[], int] = time.perf_counter_ns
) -> dict[str, dict[str, float]]:
    """Median us per step of each stage (and of the whole step) over ``steps`` steps of ``rep`` (``clock``:
    as ``stage_samples``)."""
    per_stage, calls = stage_samples(rep, steps, warmup, clock)
    return {
        k: {"median_us": float(np.median(v)), "calls_per_step": calls.get(k, steps) / steps}
        for k, v in per_stage.items()
    }


def cprofile_top(rep: Any, steps: int, warmup: int, top: int) -> str:
    import cProfile
    import io
    import pstats

    for _ in range(warmup):
        progress_afresh(rep)
        rep.step()
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(steps):
        progress_afresh(rep)
        rep.step()
    prof.disable()
    out = io.StringIO()
    pstats.Stats(prof, stream=out).sort_stats("tottime").print_stats(top)
    return out.getvalue()


def _route_file(args: argparse.Namespace) -> str:
    if args.route:
        return args.route
    import tempfile

    from studies.step_bench_ab import write_route

    path = tempfile.mkstemp(suffix=".npz")[1]
    write_route(path, args.model)
    return path


def main(argv: list[str] | None = None) -> int:
    from studies.step_bench_ab import _repeaters

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="VelocityNet ONNX")
    parser.add_argument("--route", help="ROUTE.npz from step_bench_ab --write (default: made now)")
    parser.add_argument(
        "--variant",
        choices=("raw", "patch", "light", "taught"),
        default="light",
        help="the step's image comparison (default: light; taught: light on a route with taught poses, "
        "the obstruction detector and side estimate at work)",
    )
    parser.add_argument("--steps", type=int, default=3000, help="timed steps (default: 3000)")
    parser.add_argument("--warmup", type=int, default=300, help="untimed steps first (default: 300)")
    parser.add_argument("--cprofile", type=int, metavar="N", help="print cProfile's top N functions instead")
    parser.add_argument("--cpu", action="store_true", help="time the thread's CPU, not the wall clock")
    parser.add_argument("--json", help="also write the medians here")
    args = parser.parse_args(argv)
    if args.variant == "taught":  # the light step on the benchmark's route with its taught poses
        from vtr.benchmarks.step_bench import BenchStep, sample_taught

        current, route, poses = sample_taught(128, 128)
        rep = BenchStep(args.model, 1, current, route, match_light=True, poses=poses).repeater
    else:
        rep = _repeaters(_route_file(args), args.model)[args.variant]
    if args.cprofile:
        print(cprofile_top(rep, args.steps, args.warmup, args.cprofile))
        return 0
    clock = time.thread_time_ns if args.cpu else time.perf_counter_ns
    result = profile_stages(rep, args.steps, args.warmup, clock)
    for name, s in result.items():
        depth = name.count(".")
        calls = f"  x{s['calls_per_step']:.0f}" if s["calls_per_step"] != 1 else ""
        print(f"{'  ' * depth}{name:<{40 - 2 * depth}}{s['median_us']:8.1f} us{calls}")
    if args.json:
        from vtr.benchmarks.results import write_json

        write_json(
            args.json,
            {"model": args.model, "variant": args.variant, "steps": args.steps, "stages_us": result},
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
