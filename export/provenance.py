"""What a shipped model was trained on and how: the recipe and a data summary, carried in the ONNX metadata.

Two JSON strings under ``vtr.recipe`` and ``vtr.data`` (runtime/model_meta.py ignores keys it does not
know, so older runtimes still load the model). Read them with onnxruntime (no torch needed):

    onnxruntime.InferenceSession(path).get_modelmeta().custom_metadata_map["vtr.recipe"]
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from vtr.runtime.contracts import CAMERA
from vtr.runtime.model_meta import PREFIX, CameraRange

RECIPE_KEY = PREFIX + "recipe"
DATA_KEY = PREFIX + "data"
# Data-meta fields worth keeping in the summary (the rest is per-run detail: shard names, paths).
_DATA_FIELDS = ("source", "frames_per_house", "named_houses", "noise", "seed", "held_out_houses", "camera")


def _ranges(seeds: list[int]) -> str:
    """[0, 1, 2, 5] -> "0-2,5": a readable list of house seeds."""
    out: list[str] = []
    for s in sorted(seeds):
        if out and out[-1].split("-")[-1] == str(s - 1):
            out[-1] = f"{out[-1].split('-')[0]}-{s}"
        else:
            out.append(str(s))
    return ",".join(out)


def data_summary(data_meta: Mapping[str, Any], frames: int | None = None) -> dict[str, Any]:
    """The dataset in a few fields: its source, size, houses and which houses validation held out."""
    out: dict[str, Any] = {k: data_meta[k] for k in _DATA_FIELDS if k in data_meta}
    if frames is not None:
        out["frames"] = int(frames)
    if "house_seeds" in data_meta:
        out["procedural_houses"] = f"random:{{{_ranges(list(data_meta['house_seeds']))}}}"
        out["houses"] = len(data_meta["house_seeds"]) + len(data_meta.get("named_houses", []))
    collect = data_meta.get("collect_config") or {}
    if "mix" in collect:
        out["mix"] = collect["mix"]
    if collect.get("appearances"):  # frames rendered again with the floor laid again (training.appearances)
        out["appearances"] = collect["appearances"]
    return out


_TRAIN_FIELDS = ("lr", "batch_size", "steps", "seed", "augment", "appearance_swap", "val_fraction")


def _stage(ckpt: Mapping[str, Any], init_ckpt: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """One network's settings; a fine-tune (``--init``) also names its start and that start's settings."""
    train = dict(ckpt.get("train_config") or {})
    out: dict[str, Any] = {
        "model": ckpt.get("model_config"),
        "train": {k: train[k] for k in _TRAIN_FIELDS if k in train},
    }
    if isinstance(ckpt.get("steps_done"), int):  # where training stopped (--max-minutes: before ``steps``)
        out["train"]["steps_done"] = ckpt["steps_done"]
    if ckpt.get("init"):
        out["init"] = "/".join(Path(str(ckpt["init"])).parts[-3:])  # no local absolute paths
        if init_ckpt is not None:
            out["init_stage"] = _stage(init_ckpt)
    return out


def recipe(
    ckpt: Mapping[str, Any],
    viewnet_ckpt: Mapping[str, Any] | None = None,
    init_ckpt: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The training settings of a VelocityNet checkpoint (and of the ViewNet its MPC loss used)."""
    out: dict[str, Any] = {"velocitynet": {**_stage(ckpt, init_ckpt), "loss": ckpt.get("loss_config")}}
    if viewnet_ckpt is not None:
        out["viewnet"] = _stage(viewnet_ckpt)
    return out


def provenance_props(
    ckpt: Mapping[str, Any],
    viewnet_ckpt: Mapping[str, Any] | None = None,
    init_ckpt: Mapping[str, Any] | None = None,
    frames: int | None = None,
) -> dict[str, str]:
    """ONNX metadata props for the recipe and the data summary."""
    return {
        RECIPE_KEY: json.dumps(recipe(ckpt, viewnet_ckpt, init_ckpt), sort_keys=True, separators=(",", ":")),
        DATA_KEY: json.dumps(
            data_summary(ckpt.get("data_meta") or {}, frames), sort_keys=True, separators=(",", ":")
        ),
    }


def camera_of(data_meta: Mapping[str, Any]) -> dict[str, float]:
    """The training camera's field of view and height, where the dataset recorded them (robots, bags; the
    simulator's ``camera_height`` read as ``height_m``); and, for data collected across cameras, the range
    they span (``collect_config``'s ``fov_range`` / ``height_range``, `vtr collect --fov-range`, or ``cameras``:
    one [fov deg, height m] per episode), as runtime.model_meta.ModelMeta fields.
    A dataset of one camera records no range, so its model keeps the one-camera rule."""
    cam = data_meta.get("camera") or {}
    out = {}
    if isinstance(cam.get("fov_deg"), int | float):
        out["camera_fov_deg"] = float(cam["fov_deg"])
    height = cam.get("height_m", cam.get("camera_height"))
    if isinstance(height, int | float):
        out["camera_height_m"] = float(height)
    collect = data_meta.get("collect_config") or {}
    fovs, heights = collect.get("fov_range"), collect.get("height_range")
    if (
        fovs or heights
    ):  # recorded across houses with cameras drawn from these ranges (vtr collect --fov-range)
        fovs = fovs or [out.get("camera_fov_deg", CAMERA.fov_deg)] * 2
        heights = heights or [out.get("camera_height_m", CAMERA.height_m)] * 2
        out.update(
            CameraRange((float(fovs[0]), float(fovs[1])), (float(heights[0]), float(heights[1]))).props()
        )
        out["camera_fov_deg"] = (float(fovs[0]) + float(fovs[1])) / 2
        out["camera_height_m"] = (float(heights[0]) + float(heights[1])) / 2
    cameras = data_meta.get("cameras")
    if isinstance(cameras, list) and cameras:
        try:
            pairs = [(float(f), float(h)) for f, h in cameras]
        except (TypeError, ValueError):
            raise ValueError(
                f"data meta 'cameras' must be [fov_deg, height_m] pairs, got {cameras!r:.80}"
            ) from None
        rng = CameraRange.of(pairs)
        if rng.fov_deg[0] < rng.fov_deg[1] or rng.height_m[0] < rng.height_m[1]:
            out.update(rng.props())
            # the nominal camera: the middle of the range
            out["camera_fov_deg"] = sum(rng.fov_deg) / 2
            out["camera_height_m"] = sum(rng.height_m) / 2
        else:
            out["camera_fov_deg"], out["camera_height_m"] = pairs[0]
    return out


def stamp_camera_range(path: Path, rng: CameraRange) -> list[Path]:
    """Record ``rng`` as the cameras an exported model takes (runtime.model_meta.CameraRange), in ``path`` and
    its int8 twin beside it where there is one, nothing else changed: for a model measured on held-out
    routes after its export (the shipped model's range, models/training-summary.json). Returns the files
    written (each atomically)."""
    import onnx

    from vtr.models import int8_path
    from vtr.runtime.atomic import write_bytes_atomic
    from vtr.runtime.model_meta import ModelMeta

    written = []
    for file in (Path(path), int8_path(Path(path))):
        if file != Path(path) and not file.exists():
            continue
        proto = onnx.load(str(file))
        props = {p.key: p.value for p in proto.metadata_props}
        props.update({PREFIX + k: str(v) for k, v in rng.props().items()})
        ModelMeta.from_props(props)  # still a model the runtime reads
        del proto.metadata_props[:]
        for key, value in props.items():
            proto.metadata_props.add(key=key, value=value)
        write_bytes_atomic(file, proto.SerializeToString())
        written.append(file)
    return written
