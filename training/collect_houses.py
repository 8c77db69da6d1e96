"""`vtr collect --houses N`: record across procedural houses, in parallel worker processes, into shards.

    vtr collect --houses 40 --frames-per-house 2000 --out data/houses --workers 2
    vtr collect --house-seeds 100:110 --out data/heldout
    vtr collect --houses 40 --include-house house --out data/mixed   # plus the paper-style house

Each house (``random:SEED``, sim2d.procedural, or a named map such as the paper-style ``house``) is one task: a
worker builds the simulator, drives the

"repeat" command mix (training.collect.MIXES) through every room and writes the frames straight into
memory-mapped shard files (training.shards), so neither a worker nor the parent holds the dataset.
The parent shows progress over all workers and rewrites the index after each finished house.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import time
import zlib
from concurrent.futures import FIRST_COMPLETED, wait
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from vtr.training.config import CollectConfig
from vtr.training.pool import FORK_OR_SPAWN, process_pool

_progress: Any = None  # a shared frame counter, set in each worker by _init_worker


def parse_seed_range(text: str) -> list[int]:
    """``A:B`` -> seeds A..B-1 (``A`` alone: one seed); ValueError with a one-line message otherwise."""
    a, sep, b = text.partition(":")
    try:
        lo, hi = int(a), (int(b) if sep else int(a) + 1)
    except ValueError:
        raise ValueError(f"--house-seeds: expected A:B (integers, A < B), got {text!r}") from None
    if lo < 0 or hi <= lo:
        raise ValueError(f"--house-seeds: expected 0 <= A < B, got {text!r}")
    return list(range(lo, hi))


@dataclass(frozen=True)
class HousesConfig:
    """What `vtr collect --houses` records."""

    out: str = "data/houses"  # dataset folder (index.json + .npy shards)
    seeds: tuple[int, ...] = tuple(range(20))  # procedural house seeds
    frames_per_house: int = 2000
    workers: int = 0  # worker processes; 0 = the number of CPU cores
    collect: CollectConfig = field(default_factory=lambda: CollectConfig(mix="repeat", reverse_fraction=0.2))
    named: tuple[str, ...] = ()  # named maps recorded as well (e.g. "house", the paper-style house)
    named_frames: int = 0  # frames per named map; 0 = frames_per_house

    def __post_init__(self) -> None:
        if not self.seeds and not self.named:
            raise ValueError("HousesConfig.seeds: at least one house is needed")
        if self.frames_per_house < 2:
            raise ValueError(f"HousesConfig.frames_per_house must be >= 2, got {self.frames_per_house}")
        if self.workers < 0:
            raise ValueError(f"HousesConfig.workers must be >= 0, got {self.workers}")
        if self.named_frames < 0 or 0 < self.named_frames < 2:
            raise ValueError(f"HousesConfig.named_frames must be 0 or >= 2, got {self.named_frames}")

    def tasks(self) -> list[tuple[str, int, int]]:
        """(house, seed key, frames) for every house; the key seeds the driving and names the shards."""
        # Named maps first: they are usually the larger tasks, so they should not start last.
        out = []
        for name in self.named:
            key = zlib.crc32(name.encode()) & 0x7FFFFFFF  # stable across runs, unlike hash()
            out.append((name, key, self.named_frames or self.frames_per_house))
        return out + [(f"random:{s}", s, self.frames_per_house) for s in self.seeds]


def _init_worker(counter: Any) -> None:
    global _progress
    _progress = counter
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")


def _tick() -> None:
    if _progress is not None:
        with _progress.get_lock():
            _progress.value += 1


def house_camera(cfg: CollectConfig, seed: int) -> Any:
    """The CameraConfig a house records with: the shipped camera, or one drawn for this house (``seed``) from
    ``cfg.fov_range`` and ``cfg.height_range``."""
    from vtr.runtime.contracts import CAMERA
    from vtr.sim2d.config import camera_config

    if cfg.fov_range is None and cfg.height_range is None:
        return camera_config(cfg.image_size, cfg.image_size)
    u = np.random.default_rng([cfg.seed, seed, 11]).random(2)
    f0, f1 = cfg.fov_range or (CAMERA.fov_deg, CAMERA.fov_deg)
    h0, h1 = cfg.height_range or (CAMERA.height_m, CAMERA.height_m)
    camera = (round(f0 + (f1 - f0) * u[0], 1), round(h0 + (h1 - h0) * u[1], 3))
    return camera_config(cfg.image_size, cfg.image_size, camera)


def record_house(out: str, house: str, seed: int, frames: int, cfg: CollectConfig) -> dict[str, Any]:
    """Record one house into shard files named after it; returns its index entries and tallies."""
    from vtr.runtime.atomic import atomic_path
    from vtr.sim2d import SimConfig, Simulator
    from vtr.training.appearances import appearance_cameras, render_appearances
    from vtr.training.collect import Recording, drive
    from vtr.training.shards import MAX_SHARD_FRAMES, alt_path, shard_paths

    camera = house_camera(cfg, seed)
    sim = Simulator(SimConfig(house=house, camera=camera, noise=cfg.noise))
    looks = (
        appearance_cameras(house, camera, cfg.appearances, cfg.seed * 1_000_003 + seed)
        if cfg.appearances
        else []
    )
    entries, tallies = [], {"collisions": 0, "commands": {}}
    done, part = 0, 0
    while done < frames:
        n = min(MAX_SHARD_FRAMES, frames - done)
        stem = (
            f"{seed:07d}"
            if house.startswith("random:")
            else "".join(c if c.isalnum() else "_" for c in house)
        )
        name = f"house_{stem}_{part}"
        paths = shard_paths(Path(out), name)
        shapes = {
            "images": ((n, cfg.image_size, cfg.image_size, 3), np.uint8),
            "commands": ((n, 2), np.float32),
            "poses": ((n, 3), np.float32),
            "episodes": ((n,), np.int32),
        }
        # Frames go straight to disk through memory maps at temporary paths, renamed when complete.
        with (
            atomic_path(paths["images"]) as ti,
            atomic_path(paths["commands"]) as tc,
            atomic_path(paths["poses"]) as tp,
            atomic_path(paths["episodes"]) as te,
        ):
            tmp = {"images": ti, "commands": tc, "poses": tp, "episodes": te}
            arrays = {
                k: np.lib.format.open_memmap(tmp[k], mode="w+", dtype=d, shape=s)
                for k, (s, d) in shapes.items()
            }
            rec = Recording(arrays["images"], arrays["commands"], arrays["poses"], arrays["episodes"])
            part_cfg = replace(cfg, seed=cfg.seed * 7919 + seed * 31 + part)
            drive(sim, part_cfg, np.random.default_rng([cfg.seed, seed, part]), rec, on_frame=_tick)
            if looks:  # the same poses in the house with its floor laid again (training.appearances)
                with atomic_path(alt_path(Path(out), name)) as ta:
                    alt = np.lib.format.open_memmap(ta, mode="w+", dtype=np.uint8, shape=shapes["images"][0])
                    render_appearances(looks, arrays["poses"], arrays["episodes"], alt, part_cfg.seed)
                    alt.flush()
                    del alt
            for a in arrays.values():
                a.flush()
            n_episodes, collisions, kinds = rec.n_episodes, rec.collisions, rec.kinds
            del arrays, rec  # close the memory maps before the files are renamed
        entries.append({"name": name, "frames": n, "episodes": int(n_episodes), "house": house})
        tallies["collisions"] += collisions
        for k, v in kinds.items():
            tallies["commands"][k] = tallies["commands"].get(k, 0) + v
        done += n
        part += 1
    return {"seed": seed, "entries": entries, **tallies}


def houses_meta(cfg: HousesConfig) -> dict[str, Any]:
    """The index's metadata of a dataset recorded with `cfg`."""
    return {
        "source": "vtr collect --houses",
        "house_seeds": list(cfg.seeds),
        "named_houses": list(cfg.named),
        "frames_per_house": cfg.frames_per_house,
        "noise": cfg.collect.noise,
        "seed": cfg.collect.seed,
        "collect_config": {k: v for k, v in asdict(cfg.collect).items() if k not in ("progress", "out")},
    }


def recorded_houses(cfg: HousesConfig, meta: dict[str, Any]) -> dict[int, list]:
    """The houses of `cfg` that the dataset at ``cfg.out`` already holds in full (seed key -> index entries);
    a dataset recorded with other settings is a ValueError (one line), never mixed with this one."""
    from vtr.training.shards import read_index

    doc = read_index(cfg.out)
    if not doc or not doc.get("shards"):
        return {}
    same = ("seed", "noise", "collect_config")
    if doc.get("image_size") != cfg.collect.image_size or any(doc["meta"].get(k) != meta[k] for k in same):
        raise ValueError(f"{cfg.out} holds houses recorded with other settings; choose another folder")
    by_house: dict[str, list] = {}
    for entry in doc["shards"]:
        by_house.setdefault(str(entry.get("house")), []).append(entry)
    done = {}
    for house, key, frames in cfg.tasks():
        entries = by_house.get(house, [])
        if entries and sum(int(e.get("frames", 0)) for e in entries) == frames:
            done[key] = entries
    return done


def run_houses(cfg: HousesConfig, progress: bool = True, resume: bool = False) -> dict[str, Any]:
    """Record every house of `cfg` with a pool of workers; returns a summary (frames/s included).

    ``resume``: keep the houses the folder already holds in full (recorded with the same settings) and
    record only the others: an interrupted collection loses at most the houses being recorded."""
    from tqdm import tqdm

    from vtr.training.shards import write_index

    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    workers = cfg.workers or os.cpu_count() or 1
    ctx = mp.get_context(FORK_OR_SPAWN)
    counter = ctx.Value("q", 0)
    tasks = cfg.tasks()
    total = sum(frames for _, _, frames in tasks)
    meta = houses_meta(cfg)
    entries: dict[int, list] = recorded_houses(cfg, meta) if resume else {}
    kept = sum(frames for _, k, frames in tasks if k in entries)
    summary: dict[str, Any] = {"out": str(out), "houses": len(tasks), "frames": total, "workers": workers}
    if kept:
        summary["kept_frames"] = kept
    collisions, commands = 0, {}
    bar = tqdm(total=total, desc=f"collect {len(tasks)} houses", disable=not progress, dynamic_ncols=True)
    bar.update(kept)
    t0 = time.perf_counter()
    with process_pool(workers, FORK_OR_SPAWN, _init_worker, (counter,)) as pool:
        todo = [(h, k, n) for h, k, n in tasks if k not in entries]
        pending = {pool.submit(record_house, str(out), h, k, n, cfg.collect) for h, k, n in todo}
        while pending:
            finished, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
            bar.update(kept + counter.value - bar.n)
            for fut in finished:
                res = fut.result()  # a worker's exception surfaces here
                entries[res["seed"]] = res["entries"]
                collisions += res["collisions"]
                for k, v in res["commands"].items():
                    commands[k] = commands.get(k, 0) + v
                shards = [e for _, k, _ in tasks if k in entries for e in entries[k]]
                write_index(out, cfg.collect.image_size, cfg.collect.dt, meta, shards)
    bar.update(kept + counter.value - bar.n)
    bar.close()
    elapsed = time.perf_counter() - t0
    summary.update(
        seconds=round(elapsed, 2),
        frames_per_s=round((total - kept) / elapsed, 1),
        collisions=collisions,
        commands=commands,
        episodes=sum(e["episodes"] for es in entries.values() for e in es),
    )
    return summary


def main_houses(args: Any) -> int:
    seeds = parse_seed_range(args.house_seeds) if args.house_seeds else list(range(args.houses))
    named = tuple(args.include_house or ())
    from vtr.sim2d.house import resolve_house_path

    for name in named:  # a typo is a one-line error before any worker starts or any file is written
        if not name.startswith("random:"):
            resolve_house_path(name)
    collect = CollectConfig(
        out=args.out,
        seed=args.seed,
        noise=args.noise,
        image_size=args.image_size,
        mix="repeat",
        reverse_fraction=0.2,
        fov_range=getattr(args, "fov_range", None),
        height_range=getattr(args, "height_range", None),
        appearances=getattr(args, "appearances", 0) or 0,
    )
    per_house = args.frames_per_house or max(2, args.frames // len(seeds))
    cfg = HousesConfig(
        out=args.out,
        seeds=tuple(seeds),
        frames_per_house=per_house,
        workers=args.workers,
        collect=collect,
        named=named,
        named_frames=args.include_house_frames,
    )
    print(json.dumps(run_houses(cfg, progress=not args.no_progress), indent=2))
    return 0
