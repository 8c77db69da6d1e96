"""`python -m studies.matching_study` (from the checkout's root): how well each image comparison tells
subgoals apart when the light or the room changed between teach and repeat, and what one comparison costs.

For tuning routes (taught noise-free), every ``stride``-th subgoal is viewed again from its taught pose and
from poses moved along the route, sideways and in yaw, under each repeat-time condition (benchmarks.
conditions). For each method it reports, per condition, the distance to the subgoal divided by ``gap``, the
clean distance between that subgoal and the next (what a per-subgoal switch threshold is a fraction of):

- ``at_pose``: median of distance / gap at the taught pose: must stay well below 1 (< 0.5 to switch with a
  threshold of half a gap);
- ``switchable``: fraction of subgoals whose taught-pose distance is below half their gap;
- ``monotone``: fraction of subgoals whose distance grows with every step of along-track offset, of
  lateral offset and of yaw (the rule a controller relies on);
- per offset: median distance / gap;
- ``localised``: fraction of taught-pose views whose best match over the whole route is within one
  subgoal of the right one.

Timing: microseconds per comparison of one 128x128 image against one cached subgoal, and to compute the
features of one image, beside today's ``image_error``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from vtr.evaluation.conditions import LIGHTING, SCENES, write_scene_house
from vtr.runtime.matching import MatchConfig, Matcher

#: Routes this study (and any threshold chosen from it) may look at; the held-out routes never appear here.
TUNING_ROUTES = ("kitchen_arc", "living_s_curve", "bedroom_to_study", "office_arc", "rotation")
#: Offsets from the taught pose: along-track (m), lateral (m), yaw (deg).
ALONG = (0.0, 0.02, 0.05, 0.1, 0.2)
LATERAL = (0.0, 0.03, 0.06, 0.12)
YAW = (0.0, 2.0, 5.0, 10.0)
STUDY_LIGHTING = ("bright_0.6", "bright_1.5", "colour_cast", "left_darker")
METHODS: dict[str, MatchConfig] = {
    "raw": MatchConfig(method="raw"),  # the paper's
    "patch_mean": MatchConfig(trim=0.0),
    "patch_trim25": MatchConfig(trim=0.25),
    "patch_median": MatchConfig(trim=0.5),  # the default (MatchConfig())
    "patch_full_res": MatchConfig(downsample=1, patch=8, trim=0.5),
    "patch16": MatchConfig(downsample=2, patch=16, trim=0.5),
}


def _offset(pose: np.ndarray, along: float, lateral: float, yaw_deg: float) -> tuple[float, float, float]:
    x, y, yaw = (float(v) for v in pose)
    c, s = math.cos(yaw), math.sin(yaw)
    return (x + c * along - s * lateral, y + s * along + c * lateral, yaw + math.radians(yaw_deg))


def _render(sim: Any, pose: tuple[float, float, float]) -> np.ndarray:
    from vtr.sim2d import Pose

    return sim.reset(pose=Pose(*pose), seed=0)


def _render_all(sims: dict[str, Any], poses: dict[Any, tuple[float, float, float]]) -> dict[str, Any] | None:
    """Every pose in every house, or None when one of them is not free space for the robot."""
    try:
        return {name: {k: _render(sim, p) for k, p in poses.items()} for name, sim in sims.items()}
    except ValueError:
        return None


def study(routes: tuple[str, ...], stride: int, methods: dict[str, MatchConfig]) -> dict[str, Any]:
    from vtr.evaluation.harness import route_files, teach
    from vtr.sim2d import CameraConfig, SimConfig, Simulator

    camera = CameraConfig(width=128, height=128)
    with tempfile.TemporaryDirectory() as tmp:
        sims = {"clean": Simulator(SimConfig(camera=camera, noise=0.0))}
        for scene in SCENES:
            sims[scene] = Simulator(
                SimConfig(camera=camera, noise=0.0, house=str(write_scene_house(scene, Path(tmp))))
            )
        conditions = ["clean", *STUDY_LIGHTING, *SCENES]
        # per method, per condition: lists over subgoals
        acc: dict[str, dict[str, dict[str, list[Any]]]] = {m: {c: {} for c in conditions} for m in methods}
        skipped = 0
        for path in route_files(routes):
            route, _ = teach(path, (128, 128), 0.1)
            n = len(route)
            matchers = {m: Matcher(cfg) for m, cfg in methods.items()}
            feats = {m: mt.features(route.images) for m, mt in matchers.items()}
            for i in range(0, n - 1, stride):
                # the view sequence this subgoal is judged on: (kind, offset) -> pose
                poses = {("along", a): _offset(route.poses[i], a, 0, 0) for a in ALONG}
                poses |= {("lateral", d): _offset(route.poses[i], 0, d, 0) for d in LATERAL[1:]}
                poses |= {("yaw", d): _offset(route.poses[i], 0, 0, d) for d in YAW[1:]}
                rendered = _render_all(sims, poses)
                if rendered is None:  # an offset pose inside furniture or a wall (or moved furniture)
                    skipped += 1
                    continue
                for cond in conditions:
                    light = LIGHTING.get(cond, lambda im: im)
                    views = {k: light(v) for k, v in rendered[cond if cond in sims else "clean"].items()}
                    for m, mt in matchers.items():
                        gap = max(mt.distance(feats[m][i], feats[m][i + 1]), 1e-9)
                        d = {k: mt.distance(mt.features(v), feats[m][i]) / gap for k, v in views.items()}
                        a = acc[m][cond]
                        a.setdefault("at_pose", []).append(d[("along", 0.0)])
                        for k, val in d.items():
                            a.setdefault(f"{k[0]}_{k[1]:g}", []).append(val)
                        mono = all(
                            np.all(np.diff([d[("along", 0.0)], *[d[(kind, o)] for o in offs[1:]]]) > 0)
                            for kind, offs in (("along", ALONG), ("lateral", LATERAL), ("yaw", YAW))
                        )
                        a.setdefault("monotone", []).append(mono)
                        all_d = mt.distances(mt.features(views[("along", 0.0)]), feats[m])
                        a.setdefault("localised", []).append(abs(int(np.argmin(all_d)) - i) <= 1)
    out: dict[str, Any] = {"skipped_subgoals": skipped}
    for m, by_cond in acc.items():
        out[m] = {}
        for cond, a in by_cond.items():
            row = {k: float(np.median(v)) for k, v in a.items() if k not in ("monotone", "localised")}
            row["switchable"] = float(np.mean(np.asarray(a["at_pose"]) < 0.5))
            row["monotone"] = float(np.mean(a["monotone"]))
            row["localised"] = float(np.mean(a["localised"]))
            row["subgoals"] = len(a["at_pose"])
            out[m][cond] = row
    return out


def timing(methods: dict[str, MatchConfig], repeats: int = 300) -> dict[str, dict[str, float]]:
    """Median microseconds: features of one image, and one comparison against a cached subgoal."""
    from vtr.runtime.preprocess import image_error

    rng = np.random.default_rng(0)
    a, b = (rng.integers(0, 256, (128, 128, 3), dtype=np.uint8) for _ in range(2))
    out = {}
    t = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        image_error(a, b)
        t.append(time.perf_counter() - t0)
    out["image_error"] = {"compare_us": float(np.median(t) * 1e6), "features_us": 0.0}
    for m, cfg in methods.items():
        mt = Matcher(cfg)
        fb = mt.features(b)
        tf, tc = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fa = mt.features(a)
            t1 = time.perf_counter()
            mt.distance(fa, fb)
            tc.append(time.perf_counter() - t1)
            tf.append(t1 - t0)
        out[m] = {"features_us": float(np.median(tf) * 1e6), "compare_us": float(np.median(tc) * 1e6)}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m studies.matching_study", description=__doc__.split("\n")[0]
    )
    parser.add_argument(
        "--routes", nargs="*", default=list(TUNING_ROUTES), help="tuning routes (default: %(default)s)"
    )
    parser.add_argument(
        "--stride", type=int, default=6, help="study every k-th subgoal (default: %(default)s)"
    )
    parser.add_argument(
        "--methods", nargs="*", default=list(METHODS), choices=list(METHODS), help="comparisons"
    )
    parser.add_argument("--json", type=Path, default=None, help="write the result here")
    args = parser.parse_args(argv)
    if args.stride < 1:
        print("matching_study: --stride must be >= 1", file=sys.stderr)
        return 2
    methods = {m: METHODS[m] for m in args.methods}
    result = {
        "routes": args.routes,
        "stride": args.stride,
        "timing": timing(methods),
        "methods": {m: vars(c) if hasattr(c, "__dict__") else str(c) for m, c in methods.items()},
        "study": study(tuple(args.routes), args.stride, methods),
    }
    for m, by_cond in result["study"].items():
        if m == "skipped_subgoals":
            continue
        print(
            f"{m}: {result['timing'][m]['features_us']:.0f} us features + {result['timing'][m]['compare_us']:.0f} us per comparison"
        )
        for cond, row in by_cond.items():
            print(
                f"  {cond:17s} at_pose {row['at_pose']:.2f} switchable {row['switchable']:.2f} "
                f"monotone {row['monotone']:.2f} localised {row['localised']:.2f} along_0.05 {row['along_0.05']:.2f} "
                f"yaw_5 {row['yaw_5']:.2f} lateral_0.06 {row['lateral_0.06']:.2f}"
            )
    if args.json is not None:
        from vtr.runtime.atomic import write_text_atomic

        write_text_atomic(args.json, json.dumps(result, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
