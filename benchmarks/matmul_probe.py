"""`python -m vtr.benchmarks.matmul_probe N STEPS`: median GFLOP/s of numpy's float32 N x N matmul, as one
JSON line. Run in a subprocess so that its BLAS thread count can be pinned through the environment."""

from __future__ import annotations

import json
import sys
import time

import numpy as np


def main(argv: list[str]) -> None:
    n, steps = int(argv[0]), int(argv[1])
    rng = np.random.default_rng(0)
    a = rng.standard_normal((n, n)).astype(np.float32)
    b = rng.standard_normal((n, n)).astype(np.float32)
    for _ in range(3):
        a @ b
    times = []
    for _ in range(steps):
        t0 = time.perf_counter()
        a @ b
        times.append(time.perf_counter() - t0)
    print(json.dumps({"gflops": 2.0 * n**3 / float(np.median(times)) / 1e9}))


if __name__ == "__main__":
    main(sys.argv[1:])
