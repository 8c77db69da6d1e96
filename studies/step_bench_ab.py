"""`python studies/step_bench_ab.py ROUTE.npz MODEL`: median ``Repeater.step`` with the raw error, with
patch matching and with light matching too, for whichever ``vtr`` is importable, to compare code versions.

Run it by path with ``PYTHONPATH`` set to each checkout in turn (an old one made with ``git archive REV |
tar -x -C DIR``); it uses only interfaces older checkouts have too (``OnnxPolicy``, ``LightMatchedPolicy``,
``Repeater``, ``LoopbackRobot``). ROUTE.npz holds ``current`` and ``route`` (written by ``--write`` from
``step_bench.sample_route``), so every version steps on the same frames. The three variants are stepped
round-robin in one process; prints one JSON line of medians in microseconds. ``--sections`` instead
steps each variant alone and adds the median of each call inside the step (the controller's judgement,
the matcher's features and distance, the policy, light matching, inference, the link's calls), each
measured by a wrapper around that call (about 1 us of wrapper included in each). ``--split`` steps the three
variants and inference alone round-robin and prints, per variant, the p50 and p99 of the step's compute and
of its link as the Repeater's own stage times split them (issue 19's budget: p99 compute <= 1 ms).
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np


def _repeaters(route_file: str, model: str) -> dict[str, Any]:
    """One Repeater per variant (raw, patch, light) on the saved route, each with its own policy."""
    from vtr.benchmarks.step_bench import LoopbackRobot
    from vtr.runtime.controller import ControllerConfig
    from vtr.runtime.light import LightMatchedPolicy
    from vtr.runtime.matching import MatchConfig
    from vtr.runtime.policy import OnnxPolicy
    from vtr.runtime.repeater import RepeatConfig, Repeater
    from vtr.runtime.route import Route

    data = np.load(route_file)
    current, images = data["current"], data["route"]
    n = len(images)

    def repeater(method: str, light: bool) -> Repeater:
        policy = OnnxPolicy(model, threads=1)
        route = Route(
            images=images, poses=np.zeros((n, 3)), commands=np.zeros((n, 2)), name="ab", dt=policy.meta.dt
        )
        cfg = ControllerConfig(
            match=MatchConfig(method=method), e_m_mode="fixed", e_m=1e-3, stall_steps=0, settle_steps=0
        )
        wrapped = LightMatchedPolicy(policy) if light else policy
        return Repeater(
            LoopbackRobot(current), wrapped, route, config=RepeatConfig(controller=cfg, max_steps=10**12)
        )

    return {
        "raw": repeater("raw", False),
        "patch": repeater("patch", False),
        "light": repeater("patch", True),
    }


def medians(route_file: str, model: str, steps: int, warmup: int) -> dict[str, float]:
    variants = _repeaters(route_file, model)
    samples: dict[str, list[int]] = {k: [] for k in variants}
    for i in range(warmup + steps):
        for name, rep in variants.items():
            t0 = time.perf_counter_ns()
            record = rep.step()
            elapsed = time.perf_counter_ns() - t0
            if not record.commanded:
                raise RuntimeError(f"{name}: the repeat ended ({record.status})")
            if i >= warmup:
                samples[name].append(elapsed)
    return {name: float(np.median(s)) / 1e3 for name, s in samples.items()}


def _cpu_timed(rep: Any) -> list[int]:
    """Wrap ``rep``'s controller.judge and policy.predict (instance attributes) to add this thread's CPU time
    to the returned one-item list: the step's compute without the waits for a core of a busy machine."""
    total = [0]
    for owner, method in ((rep.controller, "judge"), (rep.policy, "predict")):
        call = getattr(owner, method)

        def timed(*args: Any, _call: Any = call, **kwargs: Any) -> Any:
            t0 = time.thread_time_ns()
            try:
                return _call(*args, **kwargs)
            finally:
                total[0] += time.thread_time_ns() - t0

        setattr(owner, method, timed)
    return total


def split(route_file: str, model: str, steps: int, warmup: int) -> dict[str, dict[str, float]]:
    """p50 / p99 (microseconds) of each variant's whole step, its compute and its link (``record.latency_ms``:
    ``compute``, ``robot``), and of inference alone on the same frames, all stepped round-robin."""
    from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL
    from vtr.runtime.policy import OnnxPolicy
    from vtr.runtime.preprocess import to_nchw

    variants = _repeaters(route_file, model)
    cpu_ns = {name: _cpu_timed(rep) for name, rep in variants.items()}
    data = np.load(route_file)
    policy = OnnxPolicy(model, threads=1)
    feeds = {INPUT_CURRENT: to_nchw(data["current"]), INPUT_SUBGOAL: to_nchw(data["route"][0])}
    samples: dict[str, list[float]] = {}
    for i in range(warmup + steps):
        t0 = time.perf_counter_ns()
        policy.infer(feeds)
        if i >= warmup:
            samples.setdefault("inference", []).append((time.perf_counter_ns() - t0) / 1e3)
        for name, rep in variants.items():
            cpu_ns[name][0] = 0
            t0 = time.perf_counter_ns()
            record = rep.step()
            elapsed = (time.perf_counter_ns() - t0) / 1e3
            if not record.commanded:
                raise RuntimeError(f"{name}: the repeat ended ({record.status})")
            if i >= warmup:
                samples.setdefault(f"{name}.step", []).append(elapsed)
                samples.setdefault(f"{name}.compute", []).append(record.latency_ms["compute"] * 1e3)
                samples.setdefault(f"{name}.link", []).append(record.latency_ms["robot"] * 1e3)
                samples.setdefault(f"{name}.compute_cpu", []).append(cpu_ns[name][0] / 1e3)
    return {
        name: {"p50_us": float(np.percentile(s, 50)), "p99_us": float(np.percentile(s, 99))}
        for name, s in samples.items()
    }


# ("onnx", "_run"): the network as predict runs it since IOBinding (older checkouts: "infer")
_SECTIONS = (
    ("controller", "judge"),
    ("matcher", "features"),
    ("matcher", "distance"),
    ("policy", "predict"),
    ("policy", "match"),
    ("onnx", "infer"),
    ("onnx", "_run"),
    ("onnx", "postprocess"),
    ("robot", "step"),
    ("robot", "stop"),
)


def sections(route_file: str, model: str, steps: int, warmup: int, variant: str) -> dict[str, float]:
    """Median whole step and median of each call in it, for one variant stepped alone (microseconds)."""
    import functools

    rep = _repeaters(route_file, model)[variant]
    owners = {
        "controller": rep.controller,
        "matcher": rep.controller.matcher,
        "policy": rep.policy,
        "onnx": getattr(rep.policy, "policy", rep.policy),
        "robot": rep.robot,
    }
    samples: dict[str, list[int]] = {"step": []}

    def timed(name: str, call: Any, *args: Any, **kwargs: Any) -> Any:
        t0 = time.perf_counter_ns()
        out = call(*args, **kwargs)
        samples.setdefault(name, []).append(time.perf_counter_ns() - t0)
        return out

    for owner, method in _SECTIONS:
        call = getattr(owners[owner], method, None)
        if call is not None:  # a policy without light matching has no match
            setattr(owners[owner], method, functools.partial(timed, f"{owner}.{method}", call))
    for i in range(warmup + steps):
        if i == warmup:
            samples = {"step": []}
        timed("step", rep.step)
    return {name: float(np.median(s)) / 1e3 for name, s in samples.items()}


def write_route(route_file: str, model: str) -> None:
    """ROUTE.npz from ``step_bench.sample_route`` at the model's image size (needs a checkout that has it)."""
    from vtr.benchmarks.step_bench import sample_route
    from vtr.runtime.policy import OnnxPolicy

    current, route = sample_route(*OnnxPolicy(model).image_shape)
    with open(route_file, "wb") as f:
        np.savez(f, current=current, route=route)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("route_file", help="ROUTE.npz with 'current' and 'route'")
    parser.add_argument("model", help="VelocityNet ONNX")
    parser.add_argument("--steps", type=int, default=2000, help="timed steps per variant (default: 2000)")
    parser.add_argument("--warmup", type=int, default=200, help="untimed steps first (default: 200)")
    parser.add_argument(
        "--write", action="store_true", help="write ROUTE.npz from step_bench.sample_route first"
    )
    parser.add_argument(
        "--sections", choices=("raw", "patch", "light"), help="time the calls inside one variant"
    )
    parser.add_argument("--split", action="store_true", help="p50/p99 of each step's compute and link")
    args = parser.parse_args()
    if args.write:
        write_route(args.route_file, args.model)
    if args.sections:
        print(json.dumps(sections(args.route_file, args.model, args.steps, args.warmup, args.sections)))
    elif args.split:
        print(json.dumps(split(args.route_file, args.model, args.steps, args.warmup)))
    else:
        print(json.dumps(medians(args.route_file, args.model, args.steps, args.warmup)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
