"""The paper-sized VelocityNet through the shipped recipe, on one GPU lease (issue 20, item 6), as one script.

Issue 20 asks for the paper preset trained at least once and whether its size pays in closed loop. The recipe's
ViewNet is not what runs on the robot, so this holds it fixed (the shipped `models/viewnet.pt`, frozen) and
changes only the policy's size: three chains run side by side on the GPU, each the shipped recipe's four
VelocityNet stages (`training/recipes/shipped.toml`) at batch 64 with the same samples
(stages a, b, c: 4,000 + 4,000 + 1,500 steps of 16 = 1,000 + 1,000 + 375 of 64; the floor stage 2,475 of 64):

- `paper_s0`, `paper_s1`: `--preset paper` (32..512 channels, 2.3 M weights; the preset's bf16 autocast);
- `default_s0`: `--preset default` (the shipped size, 0.22 M weights), the control trained the same way here.

Data: the recipe's own collection (`vtr collect --houses 40 --frames-per-house 2000 --include-house house
--include-house-frames 10000 --appearances 4 --seed 0`), on the machine's cores. Every stage has a share of the
wall-clock budget by its steps (the floor stage's steps weigh 1.3: its consistency pass); a stage the budget cuts
short validates and saves as if done (its log says at which step). OUT gets `log.txt`, `summary.json` and
`part_*` (`cat part_* | tar xz`: each stage's report.json and metrics.jsonl, the weights of stages c and floors,
the job logs). Export and closed-loop evaluation happen afterwards on the CPU (`vtr export`, `vtr eval`).

    python -m studies.paper_preset_on_gpu --out $OUT --work /tmp/w --budget-s 520          # on the device
    python -m studies.paper_preset_on_gpu --out out/dry --work /tmp/dry --tiny --device cpu  # dry run, CPU
"""

from __future__ import annotations

from pathlib import Path

from studies.mpc_vs_bc import STD
from studies.train_on_gpu import PY, Session, common, lease_parser, open_session, pack, run_parallel

BATCH = 64
# (name, steps at batch 64, lr, extra flags): the shipped recipe's VelocityNet stages
STAGES: tuple[tuple[str, int, str, tuple[str, ...]], ...] = (
    ("a", 1000, "1e-3", ()),
    ("b", 1000, "3e-4", ()),
    ("c", 375, "3e-4", ()),
    ("floors", 2475, "1e-4", ("--appearance-swap", "0.5", "--w-consistency", "0.3")),
)
STEP_COST = {"floors": 1.3}  # a floor step also runs the consistency pass
CHAINS = (("paper_s0", "paper", 0), ("paper_s1", "paper", 1), ("default_s0", "default", 0))
LOADER_WORKERS = 6  # DataLoader workers per stage: a sharded dataset is gathered on the host


def stage_minutes(total_min: float) -> dict[str, float]:
    """Each stage's --max-minutes: its share of ``total_min`` by weighted steps, less a start-up allowance."""
    weights = {name: steps * STEP_COST.get(name, 1.0) for name, steps, _, _ in STAGES}
    whole = sum(weights.values())
    return {name: max(0.2, total_min * w / whole - 0.25) for name, w in weights.items()}


def chain(
    s: Session, data: Path, viewnet: str, runs: Path, preset: str, seed: int, name: str
) -> list[list[str]]:
    """The four stages of one chain, each starting from the previous stage's model."""
    cmds, prev = [], None
    minutes = stage_minutes(0.97 * s.left() / 60.0)
    size = [] if s.tiny else ["--preset", preset]  # common() names the tiny preset itself
    for stage, steps, lr, flags in STAGES:
        out = runs / f"{name}_{stage}"
        cmd = [*PY, "train", "velocitynet", "--augment", "--preprocessing", STD, "--viewnet", viewnet]
        cmd += ["--data", str(data), "--out", str(out), "--seed", str(seed), "--lr", lr, *flags]
        cmd += ["--steps", str(max(2, steps // 200)) if s.tiny else str(steps)]
        cmd += ["--batch-size", "4" if s.tiny else str(BATCH), "--max-minutes", f"{minutes[stage]:.2f}"]
        cmd += [*common(s, threads=2), *size, "--workers", "2" if s.tiny else str(LOADER_WORKERS)]
        if prev is not None:
            cmd += ["--init", str(prev / "model.pt")]
        cmds.append(cmd)
        prev = out
    return cmds


def main(argv: list[str] | None = None) -> int:
    ap = lease_parser("python -m studies.paper_preset_on_gpu", __doc__, 520.0)
    ap.add_argument(
        "--chains",
        default=",".join(c[0] for c in CHAINS),
        help=f"which chains to train (default {','.join(c[0] for c in CHAINS)})",
    )
    args = ap.parse_args(argv)
    s = open_session(args)
    data, runs = s.work / "data" / "recipe", s.work / "runs"
    houses, frames, house_frames = ("2", "60", "120") if s.tiny else ("40", "2000", "10000")
    collect = [*PY, "collect", "--houses", houses, "--frames-per-house", frames, "--include-house", "house"]
    collect += [
        "--include-house-frames",
        house_frames,
        "--appearances",
        "4",
        "--seed",
        "0",
        "--out",
        str(data),
    ]
    collect += ["--workers", str(args.workers), "--no-progress", *(["--image-size", "32"] if s.tiny else [])]
    run_parallel(s, {"collect": [collect]}, "collect")
    viewnet = "models/viewnet.pt"
    if s.tiny:  # the tiny preset cannot load the shipped (default-size) ViewNet: train a tiny one
        tiny_view = runs / "viewnet_tiny"
        view = [
            *PY,
            "train",
            "viewnet",
            "--data",
            str(data),
            "--out",
            str(tiny_view),
            "--steps",
            "3",
            *common(s),
        ]
        run_parallel(s, {"viewnet": [view]}, "viewnet")
        viewnet = str(tiny_view / "model.pt")
    chains = [c for c in CHAINS if c[0] in args.chains.split(",")]
    jobs = {name: chain(s, data, viewnet, runs, preset, seed, name) for name, preset, seed in chains}
    run_parallel(s, jobs, "velocitynet")
    last = STAGES[-1][0]
    files = [
        runs / f"{name}_{stage}" / f
        for name, _, _ in chains
        for stage, *_ in STAGES
        for f in ("report.json", "metrics.jsonl")
    ]
    files += [runs / f"{name}_{stage}" / "model.pt" for name, _, _ in chains for stage in ("c", last)]
    pack(s, files)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
