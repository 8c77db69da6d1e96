"""The paper's offline MPC loss against behaviour cloning, in closed loop (issue 20, item 4).

Every VelocityNet here is trained from nothing on the same data, for the same steps and seeds, through the
shipped ViewNet (models/viewnet.pt, held fixed); only the loss weights differ:

* MPC: the paper's loss, w1 = 0.8 (image term through ViewNet) and w2 = 0.3 (velocity term);
* BC: behaviour cloning, w1 = 0 (the velocity term alone);
* w2 = 0: the image term alone.

Two datasets with the same frames: ``clean`` (every recorded command is the one the robot executed) and
``imperfect``, the same frames relabelled as a teleoperation log would record them (`relabel`): the command
logged at frame t reached the wheels 1 or 2 steps later (lag, per episode), the base under-steers (it turned
by g x the logged turn rate, g drawn per episode in [0.7, 0.9], so the log holds w / g), and the logged
commands carry joystick noise (Gaussian, 0.03 m/s and 0.1 rad/s), clipped to the command limits. The frames,
and so the motion ViewNet sees, are the executed ones: behaviour cloning learns the log, the image term
learns the motion.

    python -m studies.mpc_vs_bc commands                 # the exact commands, in the order they were run
    python -m studies.mpc_vs_bc imperfect DATA OUT       # the relabelled dataset (symlinks the frames)
    python -m studies.mpc_vs_bc table --runs DIR --out benchmarks/results/mpc_vs_bc.md
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
from pathlib import Path

import numpy as np

from vtr.runtime.contracts import V_MAX, W_MAX

D = "/work/data/mpcbc"  # scratch folder of the run recorded in benchmarks/results/mpc_vs_bc.md
STEPS = 300  # what the shared CPU allowed for all seven runs (nice 19: ~3.5 s a step)
STD = "rgb8_hwc_to_float32_nchw_div255_channel_standardised"
#: name -> (dataset, seed, loss flags); in the order they were trained (two queues side by side).
RUNS = {
    "clean_mpc_s0": ("clean", 0, ""),
    "clean_bc_s0": ("clean", 0, "--w1 0"),
    "clean_mpc_s1": ("clean", 1, ""),
    "clean_bc_s1": ("clean", 1, "--w1 0"),
    "clean_w2zero_s0": ("clean", 0, "--w2 0"),
    "imperfect_mpc_s0": ("imperfect", 0, ""),
    "imperfect_bc_s0": ("imperfect", 0, "--w1 0"),
}
#: runs continued to this many steps afterwards (--resume), when the CPU was freer
LONGER = {"clean_mpc_s0": 600, "clean_bc_s0": 600, "imperfect_mpc_s0": 600, "imperfect_bc_s0": 600}
LAGS = (1, 2)  # steps between the logged command and the wheels, drawn per episode
GAIN = (0.7, 0.9)  # executed turn rate / logged turn rate, drawn per episode (the base under-steers)
NOISE = (0.03, 0.1)  # joystick noise on the logged (v, w), standard deviations


def commands_text() -> str:
    """The commands of the study, as run (nice 19, one thread, in the background on the shared CPU)."""
    py = "python -m vtr.cli"
    lines = [
        f"{py} collect --houses 8 --frames-per-house 2000 --include-house house --include-house-frames 6000 "
        f"--out {D}/clean --workers 1 --seed 0",
        f"python -m studies.mpc_vs_bc imperfect {D}/clean {D}/imperfect --seed 0",
        f"{py} collect --house-seeds 5720:5723 --frames-per-house 600 --out {D}/offline_eval --workers 1 --seed 7",
    ]
    for name, (data, seed, flags) in RUNS.items():
        extra = f" {flags}" if flags else ""
        lines.append(
            f"{py} train velocitynet --data {D}/{data} --viewnet models/viewnet.pt --out {D}/runs/{name} "
            f"--steps {STEPS} --val-every 100000 --seed {seed} --threads 1 --augment --preprocessing {STD} "
            f"--allow-no-gain{extra}"
        )
        lines.append(
            f"{py} export --checkpoint {D}/runs/{name}/model.pt --out {D}/onnx/{name}_s{STEPS}.onnx --force"
        )
        lines.append(
            f"{py} train evaluate --data {D}/offline_eval --viewnet models/viewnet.pt "
            f"--velocitynet {D}/runs/{name}/model.pt --json {D}/offline/{name}_s{STEPS}.json"
        )
    labels = [("shipped", "shipped"), *((n, f"{n}_s{STEPS}") for n in RUNS)]
    for name, steps in LONGER.items():
        data, seed, flags = RUNS[name]
        extra = f" {flags}" if flags else ""
        lines.append(
            f"{py} train velocitynet --data {D}/{data} --viewnet models/viewnet.pt --out {D}/runs/{name} "
            f"--steps {steps} --val-every 100000 --seed {seed} --threads 1 --augment --preprocessing {STD} "
            f"--allow-no-gain --resume{extra}"
        )
        lines.append(
            f"{py} export --checkpoint {D}/runs/{name}/model.pt --out {D}/onnx/{name}_s{steps}.onnx --force"
        )
        labels.append((name, f"{name}_s{steps}"))
    for name, label in labels:
        model = "models/velocitynet.onnx" if name == "shipped" else f"{D}/onnx/{label}.onnx"
        lines.append(
            f"{py} eval --suite conditions --routes sim2d/routes/heldout10 --controllers after "
            f"--conditions noise_0.05 --seeds 0 1 --suite-models fp32 --model {model} --workers 1 "
            f"--json {D}/eval/{label}.json"
        )
    return "\n".join(lines)


def relabel(
    commands: np.ndarray, episodes: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """The log a driver with lag, an under-steering base and a noisy joystick would have written.

    commands (T, 2): the executed command after frame t (0 on an episode's last frame); episodes (T,).
    Returns the logged commands (T, 2) and per episode (lag, gain). Last frames keep command 0."""
    out = np.zeros_like(commands)
    params = []
    for ep in np.unique(episodes):
        idx = np.flatnonzero(episodes == ep)
        pairs = idx[:-1]  # frames with a successor in the episode
        lag = int(rng.choice(LAGS))
        gain = float(rng.uniform(*GAIN))
        params.append((lag, gain))
        if len(pairs) == 0:
            continue
        # Logged at t, executed at t + lag: the log at t holds what the wheels did at t + lag.
        src = pairs[np.minimum(np.arange(len(pairs)) + lag, len(pairs) - 1)]
        logged = commands[src].astype(np.float64)
        logged[:, 1] /= gain
        logged += rng.normal(0.0, NOISE, size=logged.shape)
        logged[:, 0] = np.clip(logged[:, 0], -V_MAX, V_MAX)
        logged[:, 1] = np.clip(logged[:, 1], -W_MAX, W_MAX)
        out[pairs] = logged
    return out.astype(commands.dtype), np.asarray(params, dtype=np.float64)


def make_imperfect(src: str, dst: str, seed: int) -> dict:
    """A sharded dataset beside `src` with the same frames (symlinks) and relabelled commands."""
    srcp, dstp = Path(src).resolve(), Path(dst)
    doc = json.loads((srcp / "index.json").read_text())
    if dstp.exists():
        raise ValueError(f"{dst} exists; remove it first")
    dstp.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    diffs, lags, gains = [], [], []
    for shard in doc["shards"]:
        name = shard["name"]
        for key in ("images", "poses", "episodes"):
            os.symlink(srcp / f"{name}.{key}.npy", dstp / f"{name}.{key}.npy")
        commands = np.load(srcp / f"{name}.commands.npy")
        episodes = np.load(srcp / f"{name}.episodes.npy")
        logged, params = relabel(commands, episodes, rng)
        np.save(dstp / f"{name}.commands.npy", logged, allow_pickle=False)
        diffs.append(np.abs(logged - commands).mean(axis=0))
        lags.extend(params[:, 0])
        gains.extend(params[:, 1])
    doc["meta"] = dict(
        doc.get("meta", {}),
        relabelled={"from": str(srcp), "seed": seed, "lags": LAGS, "gain": GAIN, "noise": NOISE},
    )
    (dstp / "index.json").write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    shutil.copymode(srcp / "index.json", dstp / "index.json")
    mean_diff = np.mean(diffs, axis=0)
    return {
        "out": str(dstp),
        "episodes": len(lags),
        "lag_2_share": float(np.mean(np.asarray(lags) == 2)),
        "gain_mean": float(np.mean(gains)),
        "mean_abs_label_change_v_w": [round(float(x), 4) for x in mean_diff],
    }


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval for k successes out of n (95% by default)."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    den = 1 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return (max(0.0, mid - half), min(1.0, mid + half))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m studies.mpc_vs_bc", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    sub.add_parser("commands", help="print the study's commands")
    imp = sub.add_parser("imperfect", help="relabel a sharded dataset as an imperfect driving log")
    imp.add_argument("src")
    imp.add_argument("dst")
    imp.add_argument("--seed", type=int, default=0)
    tab = sub.add_parser("table", help="the markdown table from the evaluation and offline JSON files")
    tab.add_argument("--runs", default=D, help=f"the study's scratch folder (default {D})")
    tab.add_argument("--out", default=None, help="write the table here (default: stdout)")
    gpu = sub.add_parser(
        "table-seeds", help="the GPU lease's table: per seed, then pooled (studies/train_on_gpu)"
    )
    gpu.add_argument("eval_dir", help="folder of {data}_{loss}_s{seed}.json from `vtr eval --json`")
    gpu.add_argument("runs_dir", help="folder of the runs (report.json, metrics.jsonl)")
    args = parser.parse_args(argv)
    if args.cmd == "commands":
        print(commands_text())
        return 0
    if args.cmd == "imperfect":
        try:
            print(json.dumps(make_imperfect(args.src, args.dst, args.seed), indent=2))
        except (ValueError, OSError) as err:
            print(f"mpc_vs_bc: {err}", file=sys.stderr)
            return 2
        return 0
    from studies.mpc_vs_bc_table import render, render_seeds

    if args.cmd == "table-seeds":
        print(render_seeds(Path(args.eval_dir), Path(args.runs_dir)), end="")
        return 0

    text = render(Path(args.runs), commands_text())
    if args.out:
        Path(args.out).write_text(text)
    else:
        print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
