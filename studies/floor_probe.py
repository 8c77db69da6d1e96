"""Open-loop probe of how much a re-coloured floor moves the policy's command (issue 20, dev data only).

For poses near the taught paths of dev routes of the paper-style house (generator seeds 100-107 by default),
each (current, subgoal) pair is fed twice: the current image rendered in the taught house, and the same pose
rendered in the house with a scene change (``floor_recoloured``, ``wall_retextured``). The subgoal always
comes from the taught house, as in a repeat. The change of the command between the two is what the scene does
to the policy; the matched command is the reference the closed loop works with. A few minutes of CPU for a
model, against an hour for the closed-loop suite, so training variants can be ranked before they are run.

    python -m studies.floor_probe --model models/velocitynet.onnx [--model other.onnx ...] [--pairs 300]
"""

from __future__ import annotations

import argparse
import copy
import json
from pathlib import Path

import numpy as np

from vtr.evaluation.conditions import SCENES
from vtr.runtime.policy import OnnxPolicy
from vtr.sim2d.camera import Camera, CameraConfig
from vtr.sim2d.house import House, house_data, load_house
from vtr.sim2d.route_gen import drive, generate_route

#: How far ahead of the current taught pose the subgoal is (taught frames), and the pose perturbation.
LOOKAHEAD, LATERAL_M, YAW_RAD = 2, 0.08, 0.15


def probe_pairs(seeds: list[int], pairs: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(current poses (P, 3), subgoal poses (P, 3)) drawn along the routes' taught paths, perturbed."""
    house = load_house("house")
    paths = [drive(house, generate_route("house", s)).poses for s in seeds]
    rng = np.random.default_rng(seed)
    cur, goal = [], []
    while len(cur) < pairs:
        path = paths[int(rng.integers(len(paths)))]
        i = int(rng.integers(len(path) - LOOKAHEAD))
        x, y, yaw = path[i]
        d = rng.uniform(-LATERAL_M, LATERAL_M)
        p = (x - d * np.sin(yaw), y + d * np.cos(yaw), yaw + rng.uniform(-YAW_RAD, YAW_RAD))
        if house.clearance(p[0], p[1]) < 0.12:
            continue
        cur.append(p)
        goal.append(path[i + LOOKAHEAD])
    return np.asarray(cur), np.asarray(goal)


def render_sets(cur: np.ndarray, goal: np.ndarray, scenes: list[str], size: int) -> dict[str, np.ndarray]:
    """Images (P, H, W, 3): 'goal' and 'taught' in the taught house, one set per scene at the current poses."""
    data, _ = house_data("house")
    cfg = CameraConfig(width=size, height=size)
    houses = {"taught": data}
    for scene in scenes:
        changed = copy.deepcopy(data)
        SCENES[scene](changed)
        houses[scene] = changed
    out = {}
    for name, d in houses.items():
        cam = Camera(House(d, name), cfg)
        out[name] = np.stack([cam.render(*map(float, p)) for p in cur])
    out["goal"] = np.stack([Camera(House(data, "taught"), cfg).render(*map(float, p)) for p in goal])
    return out


def probe(model: str, images: dict[str, np.ndarray], scenes: list[str]) -> dict[str, float]:
    """RMS change of v and w (first command) against the matched pair, per scene."""
    policy = OnnxPolicy(model)
    cmd = {
        name: np.stack(
            [policy.predict(c, g)[:, 0] for c, g in zip(images[name], images["goal"], strict=True)]
        )
        for name in ["taught", *scenes]
    }
    row = {"w_rms_taught": float(np.sqrt((cmd["taught"][:, 1] ** 2).mean()))}
    for scene in scenes:
        d = cmd[scene] - cmd["taught"]
        row[f"dv_rms_{scene}"] = float(np.sqrt((d[:, 0] ** 2).mean()))
        row[f"dv_mean_{scene}"] = float(d[:, 0].mean())  # < 0: the scene slows the robot down
        row[f"dw_rms_{scene}"] = float(np.sqrt((d[:, 1] ** 2).mean()))
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", action="append", required=True)
    ap.add_argument("--pairs", type=int, default=300)
    ap.add_argument("--route-seeds", default="100:108", help="dev generator seeds A:B (paper-style house)")
    ap.add_argument("--scenes", nargs="+", default=["floor_recoloured", "wall_retextured"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    a, b = (int(v) for v in args.route_seeds.split(":"))
    if not 100 <= a < b <= 200:
        ap.error("dev route seeds are 100-199")
    size = OnnxPolicy(args.model[0]).image_shape[0]
    cur, goal = probe_pairs(list(range(a, b)), args.pairs, args.seed)
    images = render_sets(cur, goal, args.scenes, size)
    rows = {m: probe(m, images, args.scenes) for m in args.model}
    for m, row in rows.items():
        print(m, " ".join(f"{k} {v:.4f}" for k, v in row.items()))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
