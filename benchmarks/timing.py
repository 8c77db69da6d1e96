"""Wall-clock timing of callables: p50 / p99 / mean / min in milliseconds, interleaved so that load from
other processes hits every measured callable alike."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np


def summarise(samples_ns: np.ndarray) -> dict[str, float]:
    ms = samples_ns / 1e6
    return {
        "p50_ms": float(np.percentile(ms, 50)),
        "p99_ms": float(np.percentile(ms, 99)),
        "mean_ms": float(ms.mean()),
        "min_ms": float(ms.min()),
        "n": int(ms.size),
    }


def time_call(fn: Callable[[], Any], steps: int, warmup: int) -> dict[str, float]:
    """p50 / p99 / mean / min wall time of fn() in milliseconds."""
    return time_interleaved({"fn": fn}, steps, warmup)["fn"]


def time_interleaved(
    fns: dict[str, Callable[[], Any]], steps: int, warmup: int
) -> dict[str, dict[str, float]]:
    """Time several callables round-robin, so load from other processes hits all of them alike.

    Ratios between them (whole step vs inference, int8 vs fp32) are then far steadier than from
    back-to-back runs on a shared machine.
    """
    for _ in range(warmup):
        for fn in fns.values():
            fn()
    samples = {name: np.empty(steps, dtype=np.float64) for name in fns}
    for i in range(steps):
        for name, fn in fns.items():
            t0 = time.perf_counter_ns()
            fn()
            samples[name][i] = time.perf_counter_ns() - t0
    return {name: summarise(s) for name, s in samples.items()}


def stage_table(stages: dict[str, dict[str, float]], title: str) -> str:
    """A markdown table of :func:`time_interleaved`'s stages (p50 / p99 ms) under a one-line title."""
    lines = [title, "| stage | p50 ms | p99 ms |", "|---|---|---|"]
    lines += [f"| {name} | {s['p50_ms']:.3f} | {s['p99_ms']:.3f} |" for name, s in stages.items()]
    return "\n".join(lines)


def stage_bench_main(
    argv: list[str] | None,
    description: str,
    config: type,
    run: Callable[[Any], dict[str, dict[str, float]]],
    title: Callable[[Any], str],
) -> int:
    """``python -m`` entry of a stage benchmark: one thread, the config's options, the table printed."""
    import argparse
    import os

    from vtr.runtime.cliargs import OneLineParser, add_config_arguments, config_from_args

    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    parser: argparse.ArgumentParser = OneLineParser(description=description)
    add_config_arguments(parser, config)
    cfg = config_from_args(config, parser.parse_args(argv))
    print(stage_table(run(cfg), title(cfg)))
    return 0
