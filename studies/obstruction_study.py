"""How the camera-only obstruction detector (runtime.obstruction) sees a box on the path, and what it sees
when there is none: ``python -m studies.obstruction_study [--seeds 100 101 ...]``.

Development routes only: generated in the paper-style house with route seeds 100-105 (`vtr sim route
--house house --seed N`), taught noise-free. Two measurements:

- **views** (``--part views``): the box of the ``box_on_path`` scene (25 cm, on the taught path half-way
  along), the robot placed on the taught path at 1.0, 0.8, 0.6, 0.45 and 0.35 m from the box's centre
  (contact comes at 0.17 + 0.125 m); the unmatched share of the path region against the taught views at
  that point (the subgoal before it and the one after), with the box, and without it under changed light.
- **runs** (``--part runs``): closed-loop repeats by the default controller (the condition suite's
  ``after``, its own obstruction stop off: ``after_no_obstruction``) under the box and under conditions that must not stop the robot (light, a box beside the
  path, changed walls and furniture, noise, start offsets). The detector watches each view against the
  subgoals where the route localiser places the robot, without acting: when it would have fired, and how
  far from the box's nearest face the robot was then; for the other conditions, whether it fired at all.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import sys
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime.obstruction import ObstructionConfig, ObstructionDetector, moving

DEV_SEEDS = tuple(range(100, 106))
DISTANCES = (1.0, 0.8, 0.6, 0.45, 0.35)
LIGHTS = ("bright_0.6", "bright_1.5", "colour_cast", "left_darker")
RUN_CONDITIONS = (
    "box_on_path",
    "noise_0.05",
    "noise_0.10",
    "offset_10cm_10deg",
    "bright_0.6",
    "bright_1.5",
    "colour_cast",
    "left_darker",
    "obstacle_beside_path",
    "wall_retextured",
    "furniture_moved",
    "floor_recoloured",
)


def dev_route(seed: int, image_shape: tuple[int, int] = (128, 128)) -> tuple[Any, Any]:
    """(Route, RouteScript) of the generated development route ``seed`` in the paper-style house."""
    from vtr.evaluation.harness import teach
    from vtr.sim2d.route_gen import generate_route

    if seed >= 600:
        raise ValueError(f"route seeds >= 600 are held out of tuning, got {seed}")
    return teach(generate_route("house", seed), image_shape, 0.1)


def scene_house(scene: str, tmp: Path, poses: np.ndarray) -> tuple[str, dict[str, Any]]:
    from vtr.evaluation.conditions import write_scene_house

    path = write_scene_house(scene, tmp, path=poses)
    return str(path), json.loads(path.read_text(encoding="utf-8"))


def view_shares(route: Any, cfg: ObstructionConfig, tmp: Path) -> dict[str, list[float | None]]:
    """Per DISTANCES: the path region's unmatched share with the box ("box") and without it under each
    of LIGHTS, the robot on the taught path that far from the box's centre."""
    from vtr.evaluation.conditions import LIGHTING
    from vtr.evaluation.path_boxes import box_of
    from vtr.sim2d import Simulator
    from vtr.sim2d.config import Pose, SimConfig

    poses = np.asarray(route.poses, dtype=np.float64)
    house, data = scene_house("box_on_path", tmp, poses)
    poses[:, 2] = np.unwrap(poses[:, 2])
    box = box_of(data)
    assert box is not None
    detector = ObstructionDetector(route.images, route.travel_poses(), cfg)
    # the taught path, densely, up to the box: the last point that far from its centre
    t = np.linspace(0.0, 1.0, 20, endpoint=False)
    dense = np.vstack([poses[:-1, None] * (1 - t)[:, None] + poses[1:, None] * t[:, None]]).reshape(-1, 3)
    position = np.repeat(np.arange(len(poses) - 1), len(t)) + np.tile(t, len(poses) - 1)
    centre = np.asarray(box["center"])
    gap = np.hypot(*(dense[:, :2] - centre).T)
    before_box = np.arange(len(dense)) < int(np.argmin(gap))
    sims = {"box": Simulator(SimConfig(house=house)), "none": Simulator(SimConfig())}
    out: dict[str, list[float | None]] = {"box": [], **{light: [] for light in LIGHTS}}
    for d in DISTANCES:
        far = np.flatnonzero(before_box & (gap >= d))
        if not len(far):
            for key in out:
                out[key].append(None)
            continue
        k = int(far[-1])
        pose = Pose(*(float(v) for v in dense[k]))
        sims["box"].reset(pose)
        out["box"].append(detector.share(sims["box"].observe(), float(position[k])))
        sims["none"].reset(pose)
        clean = sims["none"].observe()
        for light in LIGHTS:
            out[light].append(detector.share(LIGHTING[light](clean), float(position[k])))
    return out


def watched_run(route: Any, script: Any, cond_name: str, seed: int, cfg: ObstructionConfig) -> dict[str, Any]:
    """One closed-loop repeat (the suite's ``after``) under ``cond_name`` with the detector watching."""
    from vtr.evaluation.condition_run import AFTER, CONDITIONS, cached_policy, start_pose
    from vtr.evaluation.conditions import LIGHTING, LitRobot
    from vtr.evaluation.path_boxes import box_distance, box_of
    from vtr.models import find_model
    from vtr.runtime.follower import Follower
    from vtr.runtime.light import LightMatchedPolicy
    from vtr.runtime.repeater import RepeatConfig, Repeater, StepRecord
    from vtr.sim2d import Simulator
    from vtr.sim2d.config import SimConfig
    from vtr.sim2d.local_robot import LocalRobot

    cond = CONDITIONS[cond_name]
    policy = LightMatchedPolicy(cached_policy(find_model(None), 1))
    with tempfile.TemporaryDirectory() as tmp:
        house, data = (
            scene_house(cond.scene, Path(tmp), route.poses) if cond.scene else ("house", {"furniture": []})
        )
        robot: Any = LocalRobot(Simulator(SimConfig(noise=cond.noise, house=house)))
    if cond.light:
        robot = LitRobot(robot, LIGHTING[cond.light])
    box = box_of(data) if cond_name == "box_on_path" else None
    follower = Follower.for_route(route, replace(AFTER, obstruction=False))  # the study watches, never acts
    detector = ObstructionDetector(route.images, route.travel_poses(), cfg)
    trace: list[tuple[float, float, bool, float | None]] = []  # shares, forward, robot to the box's face
    fired: dict[str, Any] = {}
    tiles: list[list[float]] = []  # each view's least distance per path-region tile
    last_vw = [(0.0, 0.0)]

    def on_step(record: StepRecord) -> None:
        if record.image is None or follower.estimate is None:
            return
        scores = detector.scores(record.image, follower.estimate.position, exhaustive=True)
        share, hidden = detector.shares(scores)
        forward = moving(*last_vw[0])  # drove or turned since the last view
        verdict = detector.growth.update(share, hidden, forward)
        tiles.append(np.round(scores, 2).tolist())
        last_vw[0] = (record.v, record.w) if record.commanded else (0.0, 0.0)
        near = None if box is None or record.pose is None else box_distance(box, *record.pose[:2])
        trace.append((share, hidden, forward, near))
        if verdict.blocked and not fired:
            fired.update(step=record.step, box_face_m=near, note=verdict.note)

    start = start_pose(route.poses[0], cond.offset, seed)
    robot.reset(pose=start, seed=seed)
    rcfg = RepeatConfig(controller=follower.cfg, dt=0.1, max_steps=int(8 * len(route) + 50))
    summary = Repeater(robot, policy, route, follower, config=rcfg, on_step=on_step).run()
    near = [t[3] for t in trace if t[3] is not None]
    return {
        "condition": cond_name,
        "status": summary.status.value,
        "fired": bool(fired),
        **fired,
        "max_fraction": max((t[0] for t in trace), default=0.0),
        "closest_face_m": min(near) if near else None,
        "steps": len(trace),
        "tiles": tiles,
        "trace": [[round(a, 3), round(b, 3), c, None if d is None else round(d, 3)] for a, b, c, d in trace],
    }


def timing(route: Any, cfg: ObstructionConfig, tmp: Path, repeats: int = 30) -> dict[str, float]:
    """Milliseconds per ``update``, median and 99th percentile of the thread's CPU time (a loaded machine's
    preemptions left out) over views x repeats: views half-way between subgoals along the taught path
    (``clear``: mostly the first stages) and with the box ahead (``box``: every stage); beside them, the
    patch matcher's features of one frame (what the follower computes every step), for scale."""
    import time

    from vtr.runtime.matching import Matcher
    from vtr.sim2d import Simulator
    from vtr.sim2d.config import Pose, SimConfig

    poses = np.asarray(route.poses, dtype=np.float64)
    house, _ = scene_house("box_on_path", tmp, poses)
    out = {}
    for name, sim_house, ks in (
        ("clear", "house", range(len(poses) - 1)),
        ("box", house, range(len(poses) // 2)),
    ):
        sim, views = Simulator(SimConfig(house=sim_house)), []
        for k in list(ks)[-40:]:
            mid = (poses[k] + poses[k + 1]) / 2
            mid[2] = poses[k, 2] + math.remainder(poses[k + 1, 2] - poses[k, 2], math.tau) / 2
            try:
                sim.reset(Pose(*mid))
            except ValueError:  # inside the box
                continue
            views.append((sim.observe(), k + 0.5))
        detector, features = ObstructionDetector(route.images, route.travel_poses(), cfg), Matcher().features
        for label in (name, "features"):
            times = []
            for _ in range(repeats):
                for view, position in views:
                    t0 = time.thread_time()
                    detector.update(view, position, True) if label == name else features(view)
                    times.append(time.thread_time() - t0)
            out[f"{label}_median_ms"] = float(np.median(times) * 1e3)
            out[f"{label}_p99_ms"] = float(np.percentile(times, 99) * 1e3)
    return out


def markdown(views: dict[int, dict[str, list[float | None]]], runs: list[dict[str, Any]]) -> str:
    def pct(x: float | None) -> str:
        return "-" if x is None else f"{x * 100:.0f}"

    lines = []
    if views:
        lines += [
            "Unmatched share of the path region (%), robot on the taught path, by distance to the box's centre:",
            "",
            "| route seed | view | " + " | ".join(f"{d:.2f} m" for d in DISTANCES) + " |",
            "|---|---|" + "---|" * len(DISTANCES),
        ]
        for seed, rows in views.items():
            for key, values in rows.items():
                name = "box" if key == "box" else f"no box, {key}"
                lines.append(f"| {seed} | {name} | " + " | ".join(pct(v) for v in values) + " |")
        lines.append("")
    if runs:
        lines += [
            "Closed-loop repeats (the default controller; the detector watches and does not act), per "
            "condition over routes and noise seeds: runs where it fired, and with the box, the robot's centre "
            "to the box's nearest face when it fired (contact at 0.17 m), min / mean / max:",
            "",
            "| condition | runs | fired | at (m): min / mean / max | largest share (%) |",
            "|---|---|---|---|---|",
        ]
        for cond in dict.fromkeys(r["condition"] for r in runs):
            rs = [r for r in runs if r["condition"] == cond]
            at = [r["box_face_m"] for r in rs if r.get("box_face_m") is not None]
            spread = f"{min(at):.2f} / {np.mean(at):.2f} / {max(at):.2f}" if at else "-"
            fired = sum(r["fired"] for r in rs)
            lines.append(
                f"| {cond} | {len(rs)} | {fired} | {spread} | {pct(max(r['max_fraction'] for r in rs))} |"
            )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Measure the obstruction detector on development routes (see the module docstring)."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--seeds", type=int, nargs="*", default=list(DEV_SEEDS), help="route seeds (< 600)")
    parser.add_argument("--part", choices=("views", "runs", "both", "timing"), default="both")
    parser.add_argument(
        "--noise-seeds", type=int, nargs="*", default=[0], help="actuation noise seeds of the runs"
    )
    parser.add_argument("--conditions", nargs="*", default=list(RUN_CONDITIONS))
    parser.add_argument("--json", type=Path, default=None, help="write every number (and the traces) here")
    args = parser.parse_args(argv)
    if any(s >= 600 for s in args.seeds):
        print("obstruction_study: route seeds >= 600 are held out of tuning", file=sys.stderr)
        return 2
    cfg = ObstructionConfig()
    views: dict[int, dict[str, list[float | None]]] = {}
    runs: list[dict[str, Any]] = []
    for seed in args.seeds:
        route, script = dev_route(seed)
        if args.part == "timing":
            with tempfile.TemporaryDirectory() as tmp:
                ms = timing(route, cfg, Path(tmp))
            print(f"route seed {seed}: " + ", ".join(f"{k} {v:.3f}" for k, v in ms.items()))
            continue
        if args.part in ("views", "both"):
            with tempfile.TemporaryDirectory() as tmp:
                views[seed] = view_shares(route, cfg, Path(tmp))
        if args.part in ("runs", "both"):
            for cond, noise_seed in itertools.product(args.conditions, args.noise_seeds):
                try:
                    run = watched_run(route, script, cond, noise_seed, cfg)
                    runs.append({"seed": seed, "noise_seed": noise_seed, **run})
                except ValueError as err:  # the scene does not fit this route (a moved table on the path)
                    print(f"seed {seed} {cond}: not run: {err}", file=sys.stderr)
                    continue
                print(
                    f"seed {seed} {cond} noise seed {noise_seed}: {run['status']}, fired {run['fired']}",
                    file=sys.stderr,
                )
    print(markdown(views, [{k: v for k, v in r.items() if k not in ("trace", "tiles")} for r in runs]))
    if args.json is not None:
        args.json.write_text(json.dumps({"views": views, "runs": runs}), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
