"""Recovery views: the robot beside the taught path, and the command that brings it back.

The offline MPC loss only ever shows VelocityNet pairs (I_i, I_{i+N}) from one recorded drive, so the goal
is always reachable along the drive itself. At repeat time the robot is never exactly on the path: it
starts 5 cm aside, actuation noise pushes it off, a subgoal is accepted a little early. A policy that never
saw such a pair does not learn to steer back; it drives parallel to the path, and a subgoal it cannot match
from the side stalls the run. The field's answer is to show the network off-path views labelled with the
correction: DAVE-2 / PilotNet's left and right cameras with shifted steering, DART's noise injection.

Here, for a sample of window starts i of a simulator dataset, the simulator renders the view from a pose
perturbed from pose_i (along the path, across it, and in yaw; free space only), and a tracking controller
(Kanayama et al. 1990, written in the robot's frame) labels it: the taught commands c_i .. c_{i+N-1} plus
feedback on the offset from pose_i,

    v = v_r cos e_th + k_along e_x
    w = w_r + v_r k_across e_y + |v_r| k_heading sin e_th + k_turn sin e_th

(|v_r| makes the heading term right when the taught drive reverses; k_turn acts in turns in place, where
v_r = 0). Training adds w_recovery * 1/N sum_n ((v - v_n)^2 + (w - w_n)^2) over a batch of recovery views
paired with the goal image I_{i+N} (``train_velocitynet(..., recovery=DIR)``).

Layout of a recovery folder (memory-mapped .npy, like training.shards)::

    recovery.json     {"format": "vtr-recovery", "format_version": 1, "dataset": ..., "dataset_frames": T,
                       "config": {...}, "parts": [{"name", "views", "house"}, ...]}
    NAME.images.npy   (M, S, S, 3) uint8  the perturbed views
    NAME.starts.npy   (M,) int64          the window start i (a frame index of the parent dataset)
    NAME.commands.npy (M, N, 2) float32   the labels
    NAME.offsets.npy  (M, 3) float32      the perturbation (along m, across m, yaw rad) from pose_i
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime.atomic import atomic_path, write_text_atomic
from vtr.runtime.contracts import V_MAX, W_MAX
from vtr.training.dataset import DatasetError, FrameData, window_starts
from vtr.training.pool import FORK_OR_SPAWN, process_pool

INDEX = "recovery.json"
FORMAT = "vtr-recovery"
FORMAT_VERSION = 1
ARRAYS = ("images", "starts", "commands", "offsets")


@dataclass(frozen=True)
class RecoveryConfig:
    """How many recovery views, how far off the path, and the gains of the labelling controller."""

    per_window: float = 0.25  # recovery views per window start of the dataset (a random sample)
    horizon: int = 2  # N: commands per label, as VelocityNet outputs
    sigma_along: float = 0.03  # m, perturbation along the taught heading (1 sigma)
    sigma_across: float = 0.05  # m, perturbation across it
    sigma_yaw_deg: float = 5.0  # deg
    clip_sigmas: float = 2.5  # perturbations are truncated at this many sigmas
    margin: float = 0.02  # m of clearance beyond the robot radius a perturbed pose needs
    # Gains: offsets along and in yaw are corrected within the MPC horizon (1 / (N dt) = 5/s), as the MPC
    # loss itself asks; the lateral offset turns into a heading correction (training/README.md compares).
    k_along: float = 5.0  # 1/s
    k_across: float = 25.0  # 1/m^2
    k_heading: float = 0.0  # 1/m
    k_turn: float = 5.0  # 1/s
    seed: int = 0
    # Appearance variants (sim2d.appearance specs, "{seed}" replaced per house and variant): a view is rendered
    # in one of them, picked at random, instead of the recorded house, so the current image comes from a
    # changed world while the label is unchanged (teach and repeat in a room that changed in between).
    variants: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not 0 < self.per_window <= 4:
            raise ValueError(f"RecoveryConfig.per_window must be in (0, 4], got {self.per_window!r}")
        if self.horizon < 1:
            raise ValueError(f"RecoveryConfig.horizon must be >= 1, got {self.horizon!r}")
        for name in ("sigma_along", "sigma_across", "sigma_yaw_deg", "clip_sigmas", "margin"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"RecoveryConfig.{name} must be >= 0, got {value!r}")


def perturb(ref: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Pose ``ref`` (x, y, yaw) moved by ``offset`` (along, across, dyaw) in its own frame."""
    x, y, yaw = (float(c) for c in ref)
    a, c, d = (float(o) for o in offset)
    return np.array(
        [x + a * math.cos(yaw) - c * math.sin(yaw), y + a * math.sin(yaw) + c * math.cos(yaw), yaw + d]
    )


def recovery_commands(
    start: np.ndarray,
    ref: np.ndarray,
    ref_commands: np.ndarray,
    cfg: RecoveryConfig,
    v_max: float = V_MAX,
    w_max: float = W_MAX,
) -> np.ndarray:
    """(N, 2) commands for a robot at ``start`` that should be at ``ref`` driving ``ref_commands`` (N, 2)."""
    dx, dy = float(ref[0] - start[0]), float(ref[1] - start[1])
    c, s = math.cos(float(start[2])), math.sin(float(start[2]))
    e_x, e_y = c * dx + s * dy, -s * dx + c * dy  # the reference in the robot's frame
    e_th = math.remainder(float(ref[2] - start[2]), 2 * math.pi)
    out = np.empty((len(ref_commands), 2), dtype=np.float32)
    for k, (v_r, w_r) in enumerate(np.asarray(ref_commands, dtype=np.float64)):
        v = v_r * math.cos(e_th) + cfg.k_along * e_x
        w = w_r + v_r * cfg.k_across * e_y + (abs(v_r) * cfg.k_heading + cfg.k_turn) * math.sin(e_th)
        out[k] = (min(max(v, -v_max), v_max), min(max(w, -w_max), w_max))
    return out


def sample_views(
    poses: np.ndarray,
    commands: np.ndarray,
    starts: np.ndarray,
    is_free: Any,
    cfg: RecoveryConfig,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For window starts ``starts``: (kept starts, perturbed poses (M, 3), offsets (M, 3), labels (M, N, 2)).

    ``is_free(x, y)`` says whether the robot fits at (x, y); a start whose three draws all land in an
    obstacle is left out."""
    sig = np.array([cfg.sigma_along, cfg.sigma_across, math.radians(cfg.sigma_yaw_deg)])
    kept, pose_out, offs, labels = [], [], [], []
    for i in starts:
        for _ in range(3):
            off = np.clip(rng.standard_normal(3), -cfg.clip_sigmas, cfg.clip_sigmas) * sig
            pose = perturb(poses[i], off)
            if is_free(pose[0], pose[1]):
                kept.append(int(i))
                pose_out.append(pose)
                offs.append(off)
                labels.append(recovery_commands(pose, poses[i], commands[i : i + cfg.horizon], cfg))
                break
    n = cfg.horizon
    if not kept:
        return (
            np.zeros(0, np.int64),
            np.zeros((0, 3)),
            np.zeros((0, 3), np.float32),
            np.zeros((0, n, 2), np.float32),
        )
    return (
        np.array(kept, np.int64),
        np.array(pose_out),
        np.array(offs, np.float32),
        np.array(labels, np.float32),
    )


def _render_house(
    out: str,
    name: str,
    house: str,
    image_size: int,
    poses: np.ndarray,
    commands: np.ndarray,
    starts: np.ndarray,
    cfg: RecoveryConfig,
    seed: int,
) -> dict[str, Any]:
    from vtr.sim2d import CameraConfig, SimConfig, Simulator

    camera = CameraConfig(width=image_size, height=image_size)
    sim = Simulator(SimConfig(house=house, camera=camera))
    radius = sim.cfg.robot_radius + cfg.margin
    rng = np.random.default_rng([cfg.seed, seed])
    kept, views, offs, labels = sample_views(
        poses, commands, starts, lambda x, y: sim.house.is_free(float(x), float(y), radius), cfg, rng
    )
    worlds = [sim.camera] + [
        Simulator(
            SimConfig(house=house, camera=camera, changes=(spec.format(seed=seed * 101 + v + 1),))
        ).camera
        for v, spec in enumerate(cfg.variants)
    ]
    pick = rng.integers(1, len(worlds), size=len(kept)) if cfg.variants else np.zeros(len(kept), int)
    images = np.empty((len(kept), image_size, image_size, 3), np.uint8)
    for k, (x, y, yaw) in enumerate(views):
        images[k] = worlds[pick[k]].render(float(x), float(y), float(yaw))
    arrays = {"images": images, "starts": kept, "commands": labels, "offsets": offs}
    for key, arr in arrays.items():
        with atomic_path(Path(out) / f"{name}.{key}.npy") as tmp, open(tmp, "wb") as f:
            np.save(f, arr, allow_pickle=False)
    return {"name": name, "views": len(kept), "house": house}


def _house_of(data: FrameData) -> tuple[np.ndarray, list[str]]:
    houses = getattr(data, "houses", None)
    if houses is not None:
        return np.asarray(houses), list(data.house_names)  # type: ignore[attr-defined]
    name = data.meta.get("map")
    if not name:
        raise DatasetError("recovery views need the simulator map of every frame; this dataset records none")
    return np.zeros(len(data), np.int32), [str(name)]


def render_recovery(
    data_path: str | os.PathLike,
    out: str | os.PathLike,
    cfg: RecoveryConfig,
    workers: int = 0,
    progress: bool = True,
) -> dict[str, Any]:
    """Render recovery views for a simulator dataset (sharded or .npz) into ``out``; returns a summary."""
    from tqdm import tqdm

    from vtr.training.dataset import load_dataset

    data = load_dataset(data_path)
    houses, names = _house_of(data)
    starts = window_starts(data.episodes, cfg.horizon + 1)
    rng = np.random.default_rng(cfg.seed)
    chosen = np.sort(
        rng.choice(
            starts,
            size=min(len(starts), int(round(cfg.per_window * len(starts)))),
            replace=len(starts) < cfg.per_window * len(starts),
        )
    )
    Path(out).mkdir(parents=True, exist_ok=True)
    tasks = []
    for h, house in enumerate(names):
        mine = chosen[houses[chosen] == h]
        if len(mine):
            stem = "".join(ch if ch.isalnum() else "_" for ch in house)
            tasks.append(
                (
                    str(out),
                    f"recovery_{stem}",
                    house,
                    data.image_size,
                    data.poses,
                    data.commands,
                    mine,
                    cfg,
                    h,
                )
            )
    parts = []
    with process_pool(workers or os.cpu_count() or 1, FORK_OR_SPAWN) as pool:
        futures = [pool.submit(_render_house, *t) for t in tasks]
        for fut in tqdm(futures, desc=f"recovery views, {len(tasks)} houses", disable=not progress):
            parts.append(fut.result())
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "dataset": str(data_path),
        "dataset_frames": len(data),
        "image_size": data.image_size,
        "config": asdict(cfg),
        "parts": parts,
    }
    write_text_atomic(Path(out) / INDEX, json.dumps(doc, indent=1, sort_keys=True) + "\n")
    return {"out": str(out), "views": sum(p["views"] for p in parts), "houses": len(parts)}


@dataclass
class RecoverySet:
    """Recovery views opened memory-mapped: images (M, S, S, 3), starts (M,), labels (M, N, 2)."""

    images: Any
    starts: np.ndarray
    commands: np.ndarray
    config: dict[str, Any]

    def __len__(self) -> int:
        return len(self.starts)


def load_recovery(path: str | os.PathLike, data: FrameData) -> RecoverySet:
    """Open a recovery folder made for ``data`` (same frame count and image size); DatasetError otherwise."""
    from vtr.training.shards import ShardedImages

    root = Path(path)
    try:
        doc = json.loads((root / INDEX).read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise DatasetError(
            f"recovery views {root}: cannot read {INDEX} ({err}); make them with `vtr collect --recovery-for`"
        ) from None
    if (
        not isinstance(doc, dict)
        or doc.get("format") != FORMAT
        or doc.get("format_version") != FORMAT_VERSION
    ):
        raise DatasetError(f"recovery views {root}: {INDEX} is not a {FORMAT} version {FORMAT_VERSION} index")
    if doc.get("dataset_frames") != len(data) or doc.get("image_size") != data.image_size:
        raise DatasetError(
            f"recovery views {root} were made for a dataset of {doc.get('dataset_frames')} frames at "
            f"{doc.get('image_size')}px, not this one ({len(data)} at {data.image_size}px); render them again"
        )
    maps, starts, commands = [], [], []
    for part in doc.get("parts") or []:
        if not part.get("views"):
            continue
        try:
            arrays = {
                k: np.load(root / f"{part['name']}.{k}.npy", mmap_mode="r", allow_pickle=False)
                for k in ARRAYS
            }
        except (OSError, ValueError) as err:
            raise DatasetError(
                f"recovery views {root}: part {part.get('name')} is missing or corrupt ({err})"
            ) from None
        maps.append(arrays["images"])
        starts.append(np.asarray(arrays["starts"], np.int64))
        commands.append(np.asarray(arrays["commands"], np.float32))
    if not maps:
        raise DatasetError(f"recovery views {root}: no views")
    return RecoverySet(
        ShardedImages(maps), np.concatenate(starts), np.concatenate(commands), doc.get("config", {})
    )
