"""Why did (or didn't) the repeat stop for the path box? One condition-suite run, with the camera-only
obstruction detector's verdict and the range scan's decision at every judged view:
``python -m studies.stop_trace ROUTE.json CONDITION [--seed S] [--controller after]``.

Development routes only (generator seeds 100-199 in the paper-style house). Per row: the step, the
localiser's position, the command, the detector's unmatched share of the path region (``share``), the
share unmatched up to its far end (``hidden``), its growth count and verdict, and the robot's centre to the
path box's nearest face (simulator truth, for the diagnosis only).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any


def trace(route_path: Path, cond_name: str, seed: int, controller: str) -> tuple[list[dict[str, Any]], dict]:
    import vtr.runtime.follower as follower_mod
    from vtr.evaluation.condition_run import CONDITIONS, CONTROLLERS, cached_policy, run_once
    from vtr.evaluation.condition_suite import SuiteConfig
    from vtr.evaluation.conditions import write_scene_house
    from vtr.evaluation.harness import teach
    from vtr.evaluation.path_boxes import box_distance, path_box

    cfg = SuiteConfig(routes=(str(route_path),), models=("fp32",), seeds=(seed,), controllers=(controller,))
    cond = CONDITIONS[cond_name]
    policy = cached_policy(cfg.model, 1)
    route, script = teach(route_path, tuple(policy.image_shape), cfg.dt)
    rows: list[dict[str, Any]] = []
    original = follower_mod.controller_for_route
    with tempfile.TemporaryDirectory() as tmp:
        house = str(write_scene_house(cond.scene, Path(tmp), path=route.poses)) if cond.scene else "house"
        box = path_box(house)

        def wrapped(r: Any, c: Any) -> Any:
            ctrl = original(r, c)
            judge = ctrl.judge

            def traced(image: Any, collided: bool = False) -> Any:
                verdict = judge(image, collided)
                o, est = getattr(ctrl, "obstructed", None), ctrl.estimate
                rows.append(
                    {
                        "pos": None if est is None else round(est.position, 2),
                        "action": verdict.decision.action.value,
                        "share": None if o is None else round(o.fraction, 2),
                        "hidden": None if o is None else round(o.hidden, 2),
                        "grow": None if o is None else o.growing_steps,
                        "blocked": None if o is None else o.blocked,
                        "beside": None if getattr(ctrl, "beside", None) is None else round(ctrl.beside.dy, 3),
                        "conf": None if est is None else round(est.confidence, 2),
                    }
                )
                return verdict

            ctrl.judge = traced
            return ctrl

        follower_mod.controller_for_route = wrapped
        import vtr.sim2d.local_robot as lr

        step = lr.LocalRobot.step

        def step_traced(self: Any, v: float, w: float, duration: float) -> Any:
            obs = step(self, v, w, duration)
            if rows:
                rows[-1].update(v=round(v, 3), w=round(w, 3))
                if box is not None:
                    rows[-1]["face"] = round(box_distance(box, *obs.pose[:2]), 3)
            return obs

        lr.LocalRobot.step = step_traced
        try:
            run = run_once(route, script, cond, house, seed, CONTROLLERS[controller], policy, cfg)
        finally:
            follower_mod.controller_for_route = original
            lr.LocalRobot.step = step
    return rows, run


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("route", type=Path)
    p.add_argument("condition")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--controller", default="after")
    p.add_argument("--every", type=int, default=1)
    p.add_argument(
        "--near", type=float, default=None, help="only rows with the box face nearer than this (m)"
    )
    args = p.parse_args(argv)
    rows, run = trace(args.route, args.condition, args.seed, args.controller)
    for i, row in enumerate(rows):
        if i % args.every and not row.get("blocked"):
            continue
        if args.near is not None and not (row.get("face") is not None and row["face"] < args.near):
            continue
        print(i, row)
    keys = ("status", "detail", "box_face_m", "box_closest_m", "waited_steps", "subgoals_reached", "on_route")
    print({k: run.get(k) for k in keys})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
