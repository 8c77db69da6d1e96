"""The training runs of one GPU lease (issue 20, items 3, 4 and 6), as one prepared script.

A lease is 15 minutes of device time, so everything that needs the GPU runs in one call, in phases, each
under a share of a wall-clock budget; every phase writes what it has before the next starts, and whatever
is finished is packed into OUT when the budget ends:

1. collect (16 cores): the MPC-vs-BC study's data (`studies/mpc_vs_bc.py`: 8 procedural houses x 2,000
   frames + the paper-style house x 6,000, seed 0) and its imperfect-driving relabel; and, beside it, data
   across cameras (houses random:0..39, 1,000 frames each, fields of view 60-120 deg, heights 0.15-0.6 m).
3b. probe (after ViewNet): VelocityNet steps per second alone on the GPU at batch 16 (the recipe's), 64 and 256.
3. ViewNet from nothing, seeds 0-4, the recipe's 4,000 steps, all at once; beside them ViewNet fine-tuned
   across cameras from the shipped one.
4. VelocityNet from nothing, the recipe's samples (9,500 steps x 16 = 152,000) as batch 64: 1,000 steps at
   lr 1e-3, then 1,375 at 3e-4, the shipped ViewNet frozen, for MPC (the paper's w1 0.8, w2 0.3) and
   behaviour cloning (w1 = 0), seeds 0-4 on clean data and 0-1 on the imperfect log; beside them the shipped
   VelocityNet fine-tuned across cameras through the fine-tuned ViewNet.

OUT receives `log.txt`, `summary.json` (every command, its wall time and exit code, the reports) and
`part_00`, `part_01`, ... (`cat part_* | tar xz`: each run's model.pt, report.json and metrics.jsonl; no
optimiser state, no ViewNet weights except the camera fine-tune's). In session 5's lease the script wrote one
37 MB `runs.tar`, which the lease does not send back (16 MiB a file); a second command on the warm machine
packed the same files into parts, as the script now does itself. Closed-loop evaluation happens afterwards on the CPU
(`vtr eval ... --model`), not here: it needs no GPU.

    python -m studies.train_on_gpu --out $OUT --work /tmp/w --budget-s 480          # on the device
    python -m studies.train_on_gpu --out out/dry --work /tmp/dry --tiny --budget-s 300  # dry run, CPU
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import tarfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from studies.mpc_vs_bc import STD, make_imperfect

PY = [sys.executable, "-m", "vtr.cli"]
SEEDS = (0, 1, 2, 3, 4)
IMPERFECT_SEEDS = (0, 1)
BATCH = 64
STAGE_A, STAGE_B = 1000, 1375  # 2,375 x 64 = the recipe's 9,500 x 16 samples; lr 1e-3 then 3e-4 as the recipe
PART_BYTES = 15 * 2**20  # the lease sends back files of at most 16 MiB
CAMERA_FT_STEPS = 1500  # ViewNet and VelocityNet fine-tunes across cameras (batch 64)


@dataclass
class Session:
    out: Path
    work: Path
    budget_s: float
    tiny: bool
    device: str
    t0: float = field(default_factory=time.monotonic)
    records: list[dict] = field(default_factory=list)

    def left(self) -> float:
        return self.budget_s - (time.monotonic() - self.t0)

    def log(self, text: str) -> None:
        line = f"[{time.monotonic() - self.t0:7.1f}s] {text}"
        print(line, flush=True)
        with open(self.out / "log.txt", "a") as fh:
            fh.write(line + "\n")

    def save(self) -> None:
        (self.out / "summary.json").write_text(json.dumps(self.records, indent=1) + "\n")


def run_parallel(s: Session, jobs: dict[str, list[list[str]]], phase: str) -> None:
    """Each job is a chain of commands run one after another; the chains run side by side."""
    procs: dict[str, tuple[subprocess.Popen, float, list[str]]] = {}
    queue = {name: list(chain) for name, chain in jobs.items()}
    logs = s.work / "logs"
    logs.mkdir(parents=True, exist_ok=True)

    def start(name: str) -> None:
        cmd = queue[name].pop(0)
        fh = open(logs / f"{name}.log", "a")
        fh.write("$ " + shlex.join(cmd) + "\n")
        fh.flush()
        procs[name] = (subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT), time.monotonic(), cmd)

    for name in queue:
        if queue[name]:
            start(name)
    while procs:
        time.sleep(1.0)
        for name, (proc, t_start, cmd) in list(procs.items()):
            rc = proc.poll()
            if rc is None:
                if s.left() < 5:  # the budget is gone: what is unfinished is left out
                    proc.kill()
                continue
            del procs[name]
            wall = time.monotonic() - t_start
            s.records.append(
                {"phase": phase, "job": name, "cmd": shlex.join(cmd), "rc": rc, "wall_s": round(wall, 1)}
            )
            s.log(f"{phase}/{name}: rc {rc} in {wall:.1f}s: {shlex.join(cmd[3:6])}")
            s.save()
            if rc == 0 and queue[name]:
                start(name)


def split_file(path: Path, out: Path, part_bytes: int) -> list[Path]:
    """`path` cut into out/part_00, part_01, ... of at most `part_bytes` (join: `cat part_* > runs.tgz`)."""
    parts = []
    with open(path, "rb") as src:
        while chunk := src.read(part_bytes):
            parts.append(out / f"part_{len(parts):02d}")
            parts[-1].write_bytes(chunk)
    return parts


def pack(s: Session, files: list[Path]) -> None:
    """``files`` (each kept as ``run/name``, those missing left out) and the job logs into one tar.gz, split into
    OUT's parts the lease sends back (at most 16 MiB a file)."""
    packed = s.work / "runs.tgz"
    with tarfile.open(packed, "w:gz", compresslevel=1) as tar:
        for f in files:
            if f.is_file():
                tar.add(f, arcname=f"{f.parent.name}/{f.name}")
        for f in sorted((s.work / "logs").glob("*.log")):
            tar.add(f, arcname=f"logs/{f.name}")
    parts = split_file(packed, s.out, PART_BYTES)
    s.log(f"packed {packed.stat().st_size / 1e6:.1f} MB in {len(parts)} parts; {len(s.records)} records")
    s.save()


def minutes(s: Session, share: float) -> str:
    """A stage's --max-minutes: its share of what is left (a stage cut short validates and saves as if done)."""
    return f"{max(0.2, share * s.left() / 60.0):.2f}"


def common(s: Session, threads: int = 1) -> list[str]:
    """The flags every training command of a lease shares: final validation only, go on without gain, the device."""
    flags = ["--threads", str(threads), "--val-every", "100000", "--allow-no-gain", "--device", s.device]
    if s.tiny:
        return [*flags, "--preset", "tiny"]
    return [*flags, "--data-on-device", "yes" if s.device.startswith("cuda") else "no"]


def lease_parser(prog: str, doc: str, budget_s: float) -> argparse.ArgumentParser:
    """The options every lease script takes: where its output and scratch go, its budget, the dry run."""
    ap = argparse.ArgumentParser(prog=prog, description=doc.split("\n")[0])
    ap.add_argument(
        "--out", required=True, help="folder for log.txt, summary.json and the packed runs (part_*)"
    )
    ap.add_argument("--work", required=True, help="scratch folder (data, runs)")
    ap.add_argument(
        "--budget-s",
        type=float,
        default=budget_s,
        help=f"wall-clock budget of the whole script (default {budget_s:g})",
    )
    ap.add_argument("--tiny", action="store_true", help="dry run: tiny preset, few frames and steps (CPU)")
    ap.add_argument("--device", default="cuda", help="training device (default cuda)")
    ap.add_argument("--workers", type=int, default=16, help="collect workers (default 16)")
    return ap


def open_session(args: argparse.Namespace) -> Session:
    """The lease's session from ``lease_parser``'s options, its output and scratch folders made."""
    s = Session(Path(args.out), Path(args.work), args.budget_s, args.tiny, args.device)
    s.out.mkdir(parents=True, exist_ok=True)
    s.work.mkdir(parents=True, exist_ok=True)
    return s


def main(argv: list[str] | None = None) -> int:
    ap = lease_parser("python -m studies.train_on_gpu", __doc__, 480.0)
    ap.add_argument(
        "--phases",
        default="viewnet,probe,velocitynet,cams",
        help="what runs besides collecting the clean data (default viewnet,probe,velocitynet,cams)",
    )
    ap.add_argument(
        "--clean-seeds", type=int, nargs="*", default=list(SEEDS), help="MPC/BC seeds on clean data"
    )
    ap.add_argument(
        "--imperfect-seeds",
        type=int,
        nargs="*",
        default=list(IMPERFECT_SEEDS),
        help="MPC/BC seeds on the imperfect log",
    )
    ap.add_argument(
        "--steps",
        type=int,
        nargs=2,
        default=[STAGE_A, STAGE_B],
        metavar=("A", "B"),
        help=f"VelocityNet steps at lr 1e-3, then at 3e-4 (default {STAGE_A} {STAGE_B})",
    )
    args = ap.parse_args(argv)
    s = open_session(args)
    w = s.work
    tiny = args.tiny
    scale = 0.02 if tiny else 1.0

    def n(x: int) -> str:
        return str(max(2, int(x * scale)))

    size = ["--image-size", "32"] if tiny else []
    # 1. collect
    clean, cams = w / "data" / "clean", w / "data" / "cams"
    houses_clean, houses_cams = ("2", "2") if tiny else ("8", "40")
    phases = set(args.phases.split(","))
    collect = {
        "collect_clean": [
            [
                *PY,
                "collect",
                "--houses",
                houses_clean,
                "--frames-per-house",
                n(2000),
                "--include-house",
                "house",
                "--include-house-frames",
                n(6000),
                "--out",
                str(clean),
                "--workers",
                str(max(1, args.workers // 2)),
                "--seed",
                "0",
                "--no-progress",
                *size,
            ]
        ],
        "collect_cams": [
            [
                *PY,
                "collect",
                "--houses",
                houses_cams,
                "--frames-per-house",
                n(1000),
                "--include-house",
                "house",
                "--include-house-frames",
                n(5000),
                "--out",
                str(cams),
                "--workers",
                str(max(1, args.workers // 2)),
                "--seed",
                "1",
                "--no-progress",
                "--fov-range",
                "60:120",
                "--height-range",
                "0.15:0.6",
                *size,
            ]
        ],
    }
    if "cams" not in phases:
        del collect["collect_cams"]
    run_parallel(s, collect, "collect")
    imperfect = w / "data" / "imperfect"
    if clean.exists() and not imperfect.exists():
        s.records.append(
            {"phase": "collect", "job": "imperfect", "result": make_imperfect(str(clean), str(imperfect), 0)}
        )
        s.save()
    runs = w / "runs"
    vel = [*PY, "train", "velocitynet", "--augment", "--preprocessing", STD]
    # 3. ViewNet from nothing, 5 seeds; ViewNet across cameras from the shipped one
    view = [*PY, "train", "viewnet"]
    jobs = {
        f"viewnet_s{seed}": [
            [
                *view,
                "--data",
                str(clean),
                "--out",
                str(runs / f"viewnet_s{seed}"),
                "--steps",
                n(4000),
                "--seed",
                str(seed),
                *common(s),
                "--max-minutes",
                minutes(s, 0.3),
            ]
        ]
        for seed in SEEDS
    }
    jobs["viewnet_cams"] = [
        [
            *view,
            "--data",
            str(cams),
            "--init",
            "models/viewnet.pt",
            "--out",
            str(runs / "viewnet_cams"),
            "--steps",
            n(CAMERA_FT_STEPS),
            "--batch-size",
            "4" if tiny else str(BATCH),
            "--lr",
            "3e-4",
            "--seed",
            "0",
            *common(s),
            "--max-minutes",
            minutes(s, 0.3),
        ]
    ]
    if tiny:  # the tiny preset cannot load the shipped (default preset) networks: train them from nothing
        jobs["viewnet_cams"] = [
            [
                *view,
                "--data",
                str(cams),
                "--out",
                str(runs / "viewnet_cams"),
                "--steps",
                "3",
                "--seed",
                "0",
                *common(s),
            ]
        ]
    if "cams" not in phases:
        del jobs["viewnet_cams"]
    if "viewnet" not in phases:
        jobs = {k: v for k, v in jobs.items() if not k.startswith("viewnet_s")}
    run_parallel(s, jobs, "viewnet")
    viewnet_for = "models/viewnet.pt" if not tiny else str(runs / "viewnet_s0" / "model.pt")
    # 3b. probe: one process alone, steps per second by batch size (metrics.jsonl's step_time_s)
    probe_steps = "6" if tiny else "100"
    probes = {}
    for b in ("16", "64", "256"):
        probes[f"probe_b{b}"] = [
            [
                *vel,
                "--viewnet",
                viewnet_for,
                "--data",
                str(clean),
                "--out",
                str(runs / f"probe_b{b}"),
                "--steps",
                probe_steps,
                "--batch-size",
                "4" if tiny else b,
                "--seed",
                "0",
                *common(s),
                "--max-minutes",
                "1",
            ]
        ]
    for name, chain in probes.items() if "probe" in phases else ():  # one at a time: alone on the GPU
        run_parallel(s, {name: chain}, "probe")
    # 4. VelocityNet: MPC vs BC at the recipe's samples; the camera fine-tune
    batch = "4" if tiny else str(BATCH)
    left_min = s.left() / 60.0
    share_a = 0.95 * args.steps[0] / sum(args.steps)  # each stage's share of the time left, by its steps
    jobs = {}
    pairs = (
        (("clean", args.clean_seeds), ("imperfect", args.imperfect_seeds)) if "velocitynet" in phases else ()
    )
    for data, seeds in pairs:
        for seed in seeds:
            for loss, flags in (("mpc", []), ("bc", ["--w1", "0"])):
                name = f"{data}_{loss}_s{seed}"
                a, b = runs / f"{name}_a", runs / name
                base = [
                    *vel,
                    "--viewnet",
                    viewnet_for,
                    "--data",
                    str(w / "data" / data),
                    "--batch-size",
                    batch,
                    "--seed",
                    str(seed),
                    *common(s),
                    *flags,
                ]
                jobs[name] = [
                    [
                        *base,
                        "--out",
                        str(a),
                        "--steps",
                        n(args.steps[0]),
                        "--lr",
                        "1e-3",
                        "--max-minutes",
                        f"{max(0.2, share_a * left_min - 0.3):.2f}",
                    ],
                    [
                        *base,
                        "--out",
                        str(b),
                        "--init",
                        str(a / "model.pt"),
                        "--steps",
                        n(args.steps[1]),
                        "--lr",
                        "3e-4",
                        "--max-minutes",
                        f"{max(0.2, (0.95 - share_a) * left_min - 0.3):.2f}",
                    ],
                ]
    cam_init = [] if tiny else ["--init", "models/velocitynet.pt"]
    if "cams" in phases:
        jobs["velocitynet_cams"] = [
            [
                *vel,
                "--viewnet",
                str(runs / "viewnet_cams" / "model.pt"),
                "--data",
                str(cams),
                "--out",
                str(runs / "velocitynet_cams"),
                *cam_init,
                "--steps",
                n(CAMERA_FT_STEPS),
                "--batch-size",
                batch,
                "--lr",
                "3e-4",
                "--seed",
                "0",
                *common(s),
                "--max-minutes",
                f"{max(0.2, 0.95 * left_min - 0.5):.2f}",
            ]
        ]
    run_parallel(s, jobs, "velocitynet")
    # pack: what finished, small files only (no ViewNet weights but the camera fine-tune's)
    keep = ("model.pt", "report.json", "metrics.jsonl")
    pack(
        s,
        [
            run / f
            for run in sorted(runs.glob("*"))
            for f in keep
            if not (run.name.startswith("viewnet_s") and f == "model.pt")
        ],
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
