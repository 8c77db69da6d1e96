"""Teach and repeat with cameras of other sizes than the model's input, through the runtime's resampling
(runtime/resample.py): completion, the repeat's mean distance to the taught path, and the resampling cost per
frame next to inference, from the same runs.

Each size is a simulated camera served over ZeroMQ (`vtr sim serve --size WxH --fov F` in-process: a
``ServerThread``), taught with `vtr teach --model` and repeated with `vtr repeat`, both through the CLI's own
functions (the teach's client waits as long as the repeat's, 5 s: the server renders in this process, and a
large frame on a loaded machine may take longer than a robot's reply); the field of view is chosen so that
the centre crop of the model's aspect sees what the shipped model was trained on (a 4:3 camera of 106.26 deg:
its square centre sees 90 deg), so sizes differ only in pixels. Routes: the generator's, in the paper-style
house (dev seeds 100-199 only).

    python -m studies.camera_sizes --route-seeds 100 101 102 --seeds 1 2 --json out/camera_sizes.json
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SIZES = ("128x128", "160x120", "320x240", "640x480")


def fov_for(width: int, height: int, seen_deg: float = 90.0) -> float:
    """The horizontal field of view of a camera whose centre square sees ``seen_deg``."""
    side = min(width, height)
    return math.degrees(2 * math.atan(math.tan(math.radians(seen_deg) / 2) * width / side))


def run_one(
    size: str, script: Path, model: str, seed: int, noise: float, house: str, work: Path
) -> dict[str, Any]:
    """Teach ``script`` and repeat it once on a ``size`` camera; the summary with the path error added."""
    from evaluation.metrics import mean_cross_track_error
    from vtr.runtime.client import SimClient
    from vtr.runtime.daemon import RepeatRunConfig
    from vtr.runtime.daemon import run as repeat
    from vtr.runtime.route import Route
    from vtr.runtime.route_script import load_route_script
    from vtr.runtime.teach import TeachConfig, model_meta, teach
    from vtr.sim2d import SimConfig, Simulator
    from vtr.sim2d.config import camera_config
    from vtr.sim2d.server import ServerConfig, ServerThread

    w, h = (int(v) for v in size.split("x"))
    sim = Simulator(SimConfig(camera=camera_config(w, h, (fov_for(w, h), 0.3)), noise=noise, house=house))
    route_path, log = work / f"{size}_{script.stem}.npz", work / f"{size}_{script.stem}_{seed}.jsonl"
    with ServerThread(sim, ServerConfig(bind="tcp://127.0.0.1:*", scan=False)) as server:
        if not route_path.exists():  # the teach's own client, with the repeat's patience (below)
            with SimClient(server.endpoint, timeout_s=5.0) as client:
                teach(client, load_route_script(str(script)), TeachConfig(), model_meta(model)).save(
                    route_path
                )
        # the server renders in this process: a large frame under load may take longer than a robot's reply
        cfg = RepeatRunConfig(server.endpoint, model, str(route_path), str(log), timeout_s=5.0, seed=seed)
        summary = repeat(cfg).to_dict()
    taught = Route.load(route_path).poses[:, :2]
    steps = [json.loads(line) for line in log.read_text().splitlines()[:-1]]
    poses = np.array([s["pose"][:2] for s in steps if s.get("pose")], dtype=np.float64)
    error = mean_cross_track_error(poses, taught) if len(poses) else math.nan
    lat = summary["mean_latency_ms"]
    return {
        "size": size,
        "route": script.stem,
        "seed": seed,
        "status": summary["status"],
        "detail": summary["detail"],
        "subgoals": f"{summary['subgoals_reached']}/{summary['subgoals_total']}",
        "mean_error_mm": round(error * 1000, 1),
        "resample_ms": round(lat.get("resample", 0.0), 3),
        "inference_ms": round(lat["inference"], 3),
    }


def table(rows: list[dict[str, Any]]) -> str:
    """One line per size: runs finished, mean path error over finished runs, mean resample and inference."""
    lines = [
        "| camera | finished | mean error (mm, finished runs) | resample ms | inference ms |",
        "|---|---|---|---|---|",
    ]
    for size in dict.fromkeys(r["size"] for r in rows):
        mine = [r for r in rows if r["size"] == size]
        done = [r for r in mine if r["status"] == "finished"]
        err = statistics.mean(r["mean_error_mm"] for r in done) if done else math.nan
        res = statistics.mean(r["resample_ms"] for r in mine)
        inf = statistics.mean(r["inference_ms"] for r in mine)
        lines.append(f"| {size} | {len(done)}/{len(mine)} | {err:.1f} | {res:.2f} | {inf:.2f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=str(ROOT / "models" / "velocitynet.onnx"))
    parser.add_argument("--sizes", nargs="+", default=list(SIZES))
    parser.add_argument("--house", default="house")
    parser.add_argument("--route-seeds", nargs="*", type=int, default=[100, 101, 102])
    parser.add_argument("--routes", nargs="*", default=[], help="ROUTE.json files besides the generated ones")
    parser.add_argument(
        "--seeds", nargs="+", type=int, default=[1], help="the repeat's actuation-noise seeds"
    )
    parser.add_argument("--noise", type=float, default=0.05)
    parser.add_argument("--json", default=None)
    args = parser.parse_args(argv)
    if any(not 100 <= s <= 199 for s in args.route_seeds) and args.house == "house":
        parser.error("dev route seeds are 100-199 (held-out discipline)")
    from vtr.sim2d.route_gen import generate_route, route_json

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        scripts = [Path(p) for p in args.routes]
        for seed in args.route_seeds:
            path = work / f"{args.house.replace(':', '_')}_{seed}.json"
            path.write_text(json.dumps(route_json(generate_route(args.house, seed))))
            scripts.append(path)
        for script in scripts:
            for size in args.sizes:
                for seed in args.seeds:
                    row = run_one(size, script, args.model, seed, args.noise, args.house, work)
                    print(json.dumps(row), file=sys.stderr, flush=True)
                    rows.append(row)
    print(table(rows))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps({"argv": sys.argv, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
