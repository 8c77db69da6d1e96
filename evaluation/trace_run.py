"""Why did a repeat stop? One condition-suite run, traced step by step.

``python -m vtr.evaluation.trace_run ROUTE CONDITION --seed S`` repeats ``ROUTE`` under ``CONDITION``
(evaluation.condition_run) exactly as the suite does, and prints, for every judged image: the subgoal
i steered to, the error to i against its threshold, the error to i+1, and where the robot truly is
against subgoal i's taught pose (distance, yaw difference and the nearest point of the taught path), and
the error the unchanged house would give at that same pose (``clean``: the camera without the change), and
how far to the left of the nearest taught pose the robot truly is (``cross_mm``) against what the floor told
the follower (``side_mm``, runtime.side_offset; NaN where it did not tell), and where the route localiser placed
the robot (``pos``, subgoal units), how sure (``conf``) and the offset common to every subgoal's distance it
took off (``match``: a changed scene raises it; NaN for the threshold rules, which have no localiser).
A clean error under the threshold with the error above it is a matching failure (the change, not the pose,
holds the robot); a clean error above it means the robot is off the pose: a steering (policy) failure. The simulator's true pose is used for this diagnosis
only. ``--json`` writes the rows.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np


def trace(
    route_path: Path | Any,
    cond_name: str,
    seed: int,
    controller: str = "after",
    model: Path | None = None,
    max_steps_factor: float = 8.0,
    base: str = "house",
    camera: tuple[float, float] | None = None,
) -> tuple[list[dict[str, Any]], str]:
    """Rows (one per judged image) and the run's final status and detail. ``route_path``: a ROUTE.json or
    a RouteScript; ``base``: the house it is taught in (a scene condition changes a copy of it);
    ``camera``: (fov deg, height m) of teach and repeat in place of the condition's (as `vtr eval --camera`)."""
    import dataclasses
    import tempfile

    from vtr.evaluation.condition_run import CONDITIONS, CONTROLLERS, cached_policy, start_pose, suite_robot
    from vtr.evaluation.conditions import write_scene_house
    from vtr.evaluation.harness import teach
    from vtr.models import find_model
    from vtr.runtime.follower import controller_for_route
    from vtr.runtime.light import LightMatchedPolicy
    from vtr.runtime.repeater import RepeatConfig, Repeater, StepRecord
    from vtr.sim2d import Pose, SimConfig, Simulator
    from vtr.sim2d.config import camera_config

    cond, method = CONDITIONS[cond_name], CONTROLLERS[controller]
    if camera is not None:
        cond = dataclasses.replace(cond, camera=camera)
    policy: Any = cached_policy(find_model(model), 1)
    # taught with the robot's own camera, as the suites teach (condition_suite, house_suite)
    route, _ = teach(route_path, tuple(policy.image_shape), 0.1, base, camera=cond.camera)
    taught = np.asarray(route.poses, dtype=np.float64)
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        house = (
            str(write_scene_house(cond.scene, Path(tmp), base, route.poses, allow_blocked=True))
            if cond.scene
            else base
        )
        h, w = route.images.shape[1:3]
        robot, _, _ = suite_robot(route, cond, house, method, 0.1)  # the robot the suite repeats on
        # the unchanged house, noise-free: what the camera would see at the same pose without the change
        camera = camera_config(w, h, cond.camera)
        clean = Simulator(SimConfig(camera=camera, noise=0.0, house=base))
        if method.match_light:
            policy = LightMatchedPolicy(policy, side_ramp=method.side_ramp)
        ctrl = controller_for_route(route, method.controller)
        robot.reset(pose=start_pose(route.poses[0], cond.offset, seed), seed=seed)

        def on_step(rec: StepRecord) -> None:
            if rec.image is None or rec.pose is None:
                return
            i = min(rec.subgoal, len(route) - 1)
            view = ctrl.matcher.features(rec.image)
            e_here = ctrl.matcher.distance(view, ctrl._feats[i])
            e_next = ctrl.matcher.distance(view, ctrl._feats[i + 1]) if i + 1 < len(route) else math.nan
            x, y, yaw = rec.pose
            try:
                seen = clean.reset(pose=Pose(x, y, yaw), seed=0)
                e_clean = ctrl.matcher.distance(ctrl.matcher.features(seen), ctrl._feats[i])
            except ValueError:  # in moved furniture's old place
                e_clean = math.nan
            gx, gy, gyaw = taught[i]
            d = np.hypot(taught[:, 0] - x, taught[:, 1] - y)
            nx, ny, nyaw = taught[int(d.argmin())]
            beside = getattr(ctrl, "beside", None)
            est = getattr(ctrl, "estimate", None)  # the route localiser's (the threshold rules have none)
            rows.append(
                {
                    "step": rec.step,
                    "from": rec.from_subgoal,
                    "i": i,
                    "action": rec.action.value if rec.action else "",
                    "error": e_here,
                    "decided_error": rec.error,
                    "clean_error": e_clean,
                    "threshold": float(ctrl.thresholds[i]),
                    "error_next": e_next,
                    "dist_mm": 1000 * math.hypot(gx - x, gy - y),
                    "dyaw_deg": math.degrees(math.remainder(yaw - gyaw, math.tau)),
                    "nearest_mm": 1000 * float(d.min()),
                    "nearest_k": int(d.argmin()),
                    "cross_mm": 1000 * ((y - ny) * math.cos(nyaw) - (x - nx) * math.sin(nyaw)),
                    "side_mm": math.nan if beside is None else 1000 * beside.dy,
                    "position": math.nan if est is None else est.position,
                    "confidence": math.nan if est is None else est.confidence,
                    "match": math.nan if est is None else est.match,
                    "best_error": math.nan if est is None else est.best_error,
                    "v": rec.v,
                    "w": rec.w,
                    "status": rec.status.value if rec.status else "",
                    "detail": rec.detail,
                }
            )

        rcfg = RepeatConfig(
            controller=method.controller, dt=0.1, max_steps=int(max_steps_factor * len(route) + 50)
        )
        summary = Repeater(robot, policy, route, ctrl, config=rcfg, on_step=on_step).run()
    return rows, f"{summary.status.value}: {summary.detail}"


def main(argv: list[str] | None = None) -> int:
    from vtr.evaluation.house_suite import parse_camera

    p = argparse.ArgumentParser(prog="python -m vtr.evaluation.trace_run", description=__doc__.split("\n")[0])
    p.add_argument("route", help="ROUTE.json, or with --house the generated route's index (sim2d.route_gen)")
    p.add_argument("--house", default=None, help="a procedural house (random:SEED) the route is generated in")
    p.add_argument("condition", help="a condition of the suite (evaluation.condition_run.CONDITIONS)")
    p.add_argument("--seed", type=int, default=0, help="noise seed (default: %(default)s)")
    p.add_argument("--controller", default="after", help="a suite controller (default: %(default)s)")
    p.add_argument("--model", type=Path, default=None, help="VelocityNet ONNX (default: the shipped one)")
    p.add_argument(
        "--camera",
        type=parse_camera,
        default=None,
        metavar="FOV,HEIGHT",
        help="the robot's camera at teach and repeat, as `vtr eval --camera` (default: the condition's)",
    )
    p.add_argument("--every", type=int, default=1, help="print every n-th row (default: %(default)s)")
    p.add_argument("--json", type=Path, default=None, help="write the rows here")
    args = p.parse_args(argv)
    from vtr.evaluation.condition_run import CONDITIONS, CONTROLLERS

    route: Any = Path(args.route)
    if args.house is not None:
        from vtr.sim2d.route_gen import generate_route

        route = generate_route(args.house, int(args.route))
    if (
        args.condition not in CONDITIONS
        or args.controller not in CONTROLLERS
        or not (args.house or route.is_file())
    ):
        print(
            f"trace_run: unknown condition/controller or no route file: {args.condition} {args.controller} "
            f"{args.route}",
            file=sys.stderr,
        )
        return 2
    rows, end = trace(
        route,
        args.condition,
        args.seed,
        args.controller,
        args.model,
        base=args.house or "house",
        camera=args.camera,
    )
    print(
        " step    i  action    error  clean  thresh  err_i+1  dist_mm  dyaw  near_mm near_k cross_mm side_mm"
        "     pos  conf  match   best"
    )
    for k, r in enumerate(rows):
        if k % args.every == 0 or r["status"] or k == len(rows) - 1:
            print(
                f"{r['step']:5d} {r['i']:4d}  {r['action'][:8]:8s} {r['error']:6.3f} {r['clean_error']:6.3f}  {r['threshold']:6.3f}  "
                f"{r['error_next']:6.3f}  {r['dist_mm']:7.1f} {r['dyaw_deg']:5.1f}  {r['nearest_mm']:7.1f} "
                f"{r['nearest_k']:5d}  {r['cross_mm']:7.1f} {r['side_mm']:7.1f} {r['position']:7.2f} "
                f"{r['confidence']:5.2f} {r['match']:6.3f} {r['best_error']:6.3f}"
            )
    print(end)
    if args.json is not None:
        import json

        from vtr.runtime.atomic import write_text_atomic

        write_text_atomic(args.json, json.dumps({"end": end, "rows": rows}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
