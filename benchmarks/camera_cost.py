"""What a camera above the furniture costs the renderer: frames of the same poses rendered with tops (the
default for such a camera), with the tops switched off, and at the shipped 0.3 m, interleaved frame by frame so
that a busy machine slows all three alike.

    python -m vtr.benchmarks.camera_cost [--poses 600]

Poses: the shipped routes of the paper-style house, driven noise-free (as `vtr bench sim` drives them).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

#: (fov deg, height m) of the cameras measured: above the coffee table (0.45 m), the bed and the cabinet (0.6 m).
CAMERAS = ((90.0, 0.55), (120.0, 0.6), (60.0, 0.6))


def poses(n: int) -> list[tuple[float, float, float]]:
    from vtr.sim2d.routes import list_routes, load_route
    from vtr.sim2d.simulator import Simulator

    sim, out = Simulator(), []
    for name in list_routes():
        route = load_route(name)
        sim.reset(pose=route.start, seed=0)
        for v, w, d in route.commands(0.1):
            sim.advance(v, w, d)
            out.append(tuple(sim.pose))
            if len(out) >= n:
                return out
    return out


def run(n: int) -> list[dict[str, float]]:
    from vtr.sim2d.camera import Camera
    from vtr.sim2d.config import CameraConfig
    from vtr.sim2d.house import load_house

    house, where = load_house("house"), poses(n)
    rows = []
    for fov, height in CAMERAS:
        cams = {
            "tops": Camera(house, CameraConfig(fov_deg=fov, camera_height=height)),
            "no_tops": Camera(house, CameraConfig(fov_deg=fov, camera_height=height)),
            "at_0.3m": Camera(house, CameraConfig(fov_deg=fov, camera_height=0.3)),
        }
        cams["no_tops"].tops = False  # the former two-layer renderer at the same height (tops missing)
        times: dict[str, list[float]] = {k: [] for k in cams}
        for p in where:
            for k, cam in cams.items():
                t0 = time.perf_counter()
                cam.render(*p)
                times[k].append(time.perf_counter() - t0)
        rows.append(
            {"fov_deg": fov, "height_m": height, **{k: 1e3 * float(np.median(v)) for k, v in times.items()}}
        )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=600, help="poses rendered per camera (default: 600)")
    args = parser.parse_args(argv)
    print("| camera | render ms, tops | tops off | same fov at 0.3 m |\n|---|---|---|---|")
    for r in run(args.poses):
        print(
            f"| {r['fov_deg']:g} deg, {r['height_m']:g} m | {r['tops']:.3f} | {r['no_tops']:.3f} | {r['at_0.3m']:.3f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
