"""The floor candidates of one GPU lease (issue 20, "any floor"), as one prepared script.

Session 4 trained the floor terms on the loaded 2-core CPU for 875 + 675 steps of batch 16 from the shipped
model (`benchmarks/results/floors_s4.md`): too few to tell the terms from their budget. Here the same
fine-tunes get ~10x the samples on the GPU, side by side, from the shipped VelocityNet through the shipped
ViewNet, on one dataset collected in two appearances of every house (`vtr collect --appearances 4`:
houses random:0..39 x 1,000 frames + the paper-style house x 8,000, seed 0; no dev or held-out house):

- ``plain``: the fine-tune alone (no floor term): what more training on this data does by itself;
- ``swap``: ``--appearance-swap 0.5`` (half the windows pair the two appearances);
- ``cons``: swap 0.5 and ``--w-consistency 1.0`` (session 4's candidate C);
- ``cons03``: swap 0.5 and ``--w-consistency 0.3`` (C drove 16% slower on matching floors: less of it).

Each runs ``--steps`` at batch 64, lr 1e-4 (the floors recipe's last stage), under a share of the budget;
OUT receives `log.txt`, `summary.json` and `part_*` (`cat part_* | tar xz`: each run's model.pt,
report.json, metrics.jsonl and its log). Export and closed-loop evaluation happen afterwards on the CPU.

    python -m studies.floors_on_gpu --out $OUT --work /tmp/w --budget-s 460          # on the device
    python -m studies.floors_on_gpu --out out/dry --work /tmp/dry --tiny --device cpu  # dry run, CPU
"""

from __future__ import annotations

from studies.mpc_vs_bc import STD
from studies.train_on_gpu import PY, common, lease_parser, open_session, pack, run_parallel

#: name -> the flags that make the candidate (all share the rest).
CANDIDATES: dict[str, list[str]] = {
    "plain": [],
    "swap": ["--appearance-swap", "0.5"],
    "cons": ["--appearance-swap", "0.5", "--w-consistency", "1.0"],
    "cons03": ["--appearance-swap", "0.5", "--w-consistency", "0.3"],
}


def main(argv: list[str] | None = None) -> int:
    ap = lease_parser("python -m studies.floors_on_gpu", __doc__, 460.0)
    ap.add_argument("--steps", type=int, default=3000, help="steps of each candidate (default 3000)")
    ap.add_argument(
        "--candidates",
        default=",".join(CANDIDATES),
        help=f"which candidates run (default {','.join(CANDIDATES)})",
    )
    args = ap.parse_args(argv)
    s = open_session(args)
    data, runs = s.work / "data" / "floors", s.work / "runs"
    tiny = args.tiny
    collect = [
        *PY,
        "collect",
        "--houses",
        "2" if tiny else "40",
        "--frames-per-house",
        "40" if tiny else "1000",
        "--include-house",
        "house",
        "--include-house-frames",
        "120" if tiny else "8000",
        "--appearances",
        "4",
        "--out",
        str(data),
        "--workers",
        str(args.workers),
        "--seed",
        "0",
        "--no-progress",
        *(["--image-size", "32"] if tiny else []),
    ]
    run_parallel(s, {"collect": [collect]}, "collect")
    # the tiny preset cannot load the shipped (default preset) networks: from nothing through a 3-step ViewNet
    viewnet = "models/viewnet.pt"
    init = ["--init", "models/velocitynet.pt"]
    if tiny:
        viewnet, init = str(runs / "viewnet" / "model.pt"), []
        tiny_view = [*PY, "train", "viewnet", "--data", str(data), "--out", str(runs / "viewnet")]
        run_parallel(s, {"viewnet": [[*tiny_view, "--steps", "3", *common(s)]]}, "viewnet")
    minutes = f"{max(0.2, 0.93 * s.left() / 60.0 - 0.5):.2f}"
    jobs = {
        name: [
            [
                *PY,
                "train",
                "velocitynet",
                "--augment",
                "--preprocessing",
                STD,
                "--viewnet",
                viewnet,
                *init,
                "--data",
                str(data),
                "--out",
                str(runs / name),
                "--steps",
                str(4 if tiny else args.steps),
                "--batch-size",
                "4" if tiny else "64",
                "--lr",
                "1e-4",
                "--seed",
                "0",
                *common(s),
                *flags,
                "--max-minutes",
                minutes,
            ]
        ]
        for name, flags in CANDIDATES.items()
        if name in args.candidates.split(",")
    }
    run_parallel(s, jobs, "velocitynet")
    pack(s, [runs / name / f for name in jobs for f in ("model.pt", "report.json", "metrics.jsonl")])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
