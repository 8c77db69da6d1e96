"""`python -m vtr.benchmarks.memory_probe MODEL STEPS H W`: peak resident memory of a process that imports
only the runtime (torch, OpenCV, pymunk and matplotlib blocked before anything loads) and runs control
steps (``Repeater.step`` on a loopback link), printed as one JSON line."""

from __future__ import annotations

import sys

for _blocked in ("torch", "cv2", "pymunk", "matplotlib"):
    sys.modules[_blocked] = None  # type: ignore[assignment]

import json  # noqa: E402
import resource  # noqa: E402

import numpy as np  # noqa: E402

from vtr.benchmarks.step_bench import BenchStep  # noqa: E402


def hwm_mb() -> float:
    """VmHWM: this process's own peak. ru_maxrss also carries the parent's high-water mark across fork +
    exec on Linux, so it would report the benchmark process, not this one."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main(argv: list[str]) -> None:
    model, steps, h, w = argv[0], int(argv[1]), int(argv[2]), int(argv[3])
    before = hwm_mb()
    rng = np.random.default_rng(0)
    subgoal = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    current = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    step = BenchStep(model, 1, current, subgoal)
    for _ in range(steps):
        step()
    heavy = sorted(
        m for m in ("torch", "cv2", "pymunk", "matplotlib", "onnx") if sys.modules.get(m) is not None
    )
    print(
        json.dumps(
            {
                "peak_rss_mb": hwm_mb(),
                "rss_after_imports_mb": before,
                "steps": steps,
                "ru_maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                "heavy_modules_loaded": heavy,
                "step": step.name,
            }
        )
    )


if __name__ == "__main__":
    main(sys.argv[1:])
