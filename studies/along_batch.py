"""Time ``SideOffset.along`` (the route's end registered on the floor, every step of a route's last two gaps) of
whichever ``vtr`` is importable, on the latency benchmark's sample route: the best of 5 repeats of 100 calls, for
9 and 13 offsets. Run once per checkout, alternating: ``PYTHONPATH=CHECKOUT python studies/along_batch.py``."""

from __future__ import annotations

import timeit

import numpy as np

from vtr.benchmarks.step_bench import sample_taught
from vtr.runtime.floor_view import Camera
from vtr.runtime.frame import Frame
from vtr.runtime.side_offset import SideOffset


def main() -> None:
    _, route, poses = sample_taught(128, 128)
    side = SideOffset(route, poses, Camera())
    k = len(route) - 1
    view = Frame.decoded(route[k - 1])
    for n in (9, 13):
        ahead = (np.arange(n) - n // 2) * side.along_step
        best = min(timeit.repeat(lambda: side.along(view, k, ahead), number=100, repeat=5)) / 100
        print(f"{n} offsets: {best * 1e6:.0f} us a call")


if __name__ == "__main__":
    main()
