"""The side estimate of two checkouts on the same recorded calls: bit for bit, and its CPU per call.

``python -m vtr.benchmarks.latency_side_replay record CALLS.pkl eval ARGS...`` runs ``vtr eval ARGS`` with
every ``SideOffset.estimate`` call recorded (the view's image, the position, and the registration's route
views, poses and camera) into CALLS.pkl (a study file: pickle, hundreds of MB for a few routes).
``python -m vtr.benchmarks.latency_side_replay compare BASE_CHECKOUT CALLS.pkl`` replays each call through
BASE_CHECKOUT's ``runtime/side_offset.py`` and this checkout's in one process, interleaved call by call, and
prints how many give the same (dy, psi, rows) and the mean CPU per call of each. Both use this checkout's
``floor_view`` and ``matching`` (BASE's side_offset imports them), so a change there is not compared.
"""

from __future__ import annotations

import importlib.util
import pickle
import sys
import time
from typing import Any

import numpy as np


def record(out: str, argv: list[str]) -> int:
    from vtr.runtime import side_offset

    regs: dict[int, dict[str, Any]] = {}
    estimate = side_offset.SideOffset.estimate

    def recorded(self: Any, view: Any, position: float) -> Any:
        reg = regs.setdefault(
            id(self), {"subgoals": self.subgoals, "poses": self.poses, "camera": self.camera, "calls": []}
        )
        reg["calls"].append((np.array(getattr(view, "image", view)), float(position)))
        return estimate(self, view, position)

    side_offset.SideOffset.estimate = recorded  # type: ignore[method-assign]
    from vtr.cli import main

    try:
        return main(argv) or 0
    finally:
        with open(out, "wb") as f:
            pickle.dump(list(regs.values()), f)
        print(f"recorded {sum(len(r['calls']) for r in regs.values())} calls of {len(regs)} routes")


def compare(base_checkout: str, calls: str) -> int:
    from vtr.runtime import side_offset as new
    from vtr.runtime.frame import Frame

    spec = importlib.util.spec_from_file_location(
        "base_side_offset", f"{base_checkout}/runtime/side_offset.py"
    )
    assert spec is not None and spec.loader is not None
    base = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = base  # dataclasses look their module up
    spec.loader.exec_module(base)

    def told(est: Any) -> tuple[float, float, int] | None:
        return None if est is None else (est.dy, est.psi, est.rows)

    with open(calls, "rb") as f:
        regs = pickle.load(f)
    same = none = n = 0
    cpu = [0, 0]
    for reg in regs:
        sides = [m.SideOffset(reg["subgoals"], reg["poses"], reg["camera"]) for m in (base, new)]
        for image, position in reg["calls"]:
            found = []
            for i, side in enumerate(sides):
                frame = Frame.decoded(image)
                side.floor.pool(frame)  # pooled once per frame in the step, by the localiser's matcher
                t0 = time.thread_time_ns()
                found.append(told(side.estimate(frame, position)))
                cpu[i] += time.thread_time_ns() - t0
            n += 1
            same += found[0] == found[1]
            none += found[0] is None and found[1] is None
    print(
        f"{n} calls: {same} the same ({none} no estimate in both), {n - same} differ; mean CPU per call "
        f"{base_checkout} {cpu[0] / n / 1e3:.0f} us, this checkout {cpu[1] / n / 1e3:.0f} us"
    )
    return 0 if same == n else 1


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) >= 2 and args[0] == "record":
        return record(args[1], args[2:])
    if len(args) == 3 and args[0] == "compare":
        return compare(args[1], args[2])
    print(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main())
