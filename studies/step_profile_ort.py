"""`python -m studies.step_profile_ort [MODEL] [--int8 INT8]`: does an onnxruntime session option, or the int8
twin, make VelocityNet's inference cheaper on this machine, and does it keep the output's bits?

One thread, as the runtime runs (``OnnxPolicy``: intra-op 1, inter-op 1, sequential, all graph optimisations,
onnxruntime's documented defaults apart from the thread count). Each variant's session is run round-robin on
the benchmark's frames (``step_bench.sample_route``, standardised as the model's metadata says) and timed in
this thread's CPU time, so waits for a core on a busy machine do not count; the output is compared with the
runtime's session bit for bit. A variant that changes the bits changes decisions: not a free speed-up.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import numpy as np


def _session(path: str, level: Any = None, **config: str) -> Any:
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.graph_optimization_level = level or ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    for key, value in config.items():
        options.add_session_config_entry(key, value)
    return ort.InferenceSession(path, options, providers=["CPUExecutionProvider"])


def main(argv: list[str] | None = None) -> int:
    import onnxruntime as ort

    from vtr.benchmarks.step_bench import sample_route
    from vtr.runtime.policy import OnnxPolicy
    from vtr.runtime.preprocess import to_nchw

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", nargs="?", default="models/velocitynet.onnx")
    parser.add_argument("--int8", default="models/velocitynet-int8.onnx", help="the int8 twin ('' for none)")
    parser.add_argument("--runs", type=int, default=1500, help="timed runs per variant (default: 1500)")
    args = parser.parse_args(argv)
    meta = OnnxPolicy(args.model).meta
    current, route = sample_route(meta.image_height, meta.image_width)
    feeds = {
        "current": to_nchw(current, meta.preprocessing),
        "subgoal": to_nchw(route[3], meta.preprocessing),
    }
    level = ort.GraphOptimizationLevel
    variants = {
        "runtime's (all optimisations)": _session(args.model),
        "extended optimisations": _session(args.model, level.ORT_ENABLE_EXTENDED),
        "basic optimisations": _session(args.model, level.ORT_ENABLE_BASIC),
        "denormals as zero": _session(args.model, **{"session.set_denormal_as_zero": "1"}),
        "no spinning": _session(args.model, **{"session.intra_op.allow_spinning": "0"}),
    }
    if args.int8:
        variants["int8 twin"] = _session(args.int8)
    reference = next(iter(variants.values())).run(None, feeds)[0]
    samples: dict[str, list[int]] = {name: [] for name in variants}
    for i in range(args.runs + 100):
        for name, session in variants.items():
            t0 = time.thread_time_ns()
            session.run(None, feeds)
            if i >= 100:
                samples[name].append(time.thread_time_ns() - t0)
    print(f"onnxruntime {ort.__version__}, {args.runs} runs each, CPU ms of this thread, p50 / p99")
    for name, session in variants.items():
        out = session.run(None, feeds)[0]
        same = (
            "same bits"
            if np.array_equal(out, reference)
            else f"differs by {np.abs(out - reference).max():.1e}"
        )
        s = np.array(samples[name]) / 1e6
        print(f"  {name:32s} {np.percentile(s, 50):.3f} / {np.percentile(s, 99):.3f}  {same}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
