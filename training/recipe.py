"""Training recipes: what `vtr train all` runs, read from a TOML file (training/recipes/NAME.toml or a path).

    vtr train all                              # the shipped model's recipe (shipped.toml)
    vtr train all --recipe paper-house         # the earlier one-house recipe
    vtr train all --recipe my_recipe.toml

A recipe names a preset (training/config.py), a dataset path and how to record it, the ViewNet stage, one or
more VelocityNet stages (a later stage may start from an earlier one: ``init = "NAME"``) and the export::

    preset = "default"
    data = "data/houses40"
    [collect]                  # houses = 0: the preset's one-house collection into an .npz
    houses = 40                # random:0 .. random:39, a folder of shards (training/collect_houses.py)
    frames_per_house = 2000
    include_house = ["house"]
    include_house_frames = 10000
    [viewnet]
    steps = 4000
    [[velocitynet]]
    name = "velocitynet"
    steps = 4000
    [[velocitynet]]
    name = "velocitynet_b"
    init = "velocitynet"
    lr = 3e-4
    [export]
    int8 = true

Stage keys are the stage options of `vtr train viewnet|velocitynet` (``STAGE_KEYS``); an unknown key, a
missing file or a bad value is a ValueError with one line.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from vtr.runtime.atomic import write_text_atomic

RECIPES = Path(__file__).resolve().parent / "recipes"
RECORD = "recipe.json"  # the recipe a run folder holds, to tell a resumed run from another one
DEFAULT = "shipped"

#: Stage options a recipe may set, with their types (names as the command-line options, underscores).
STAGE_KEYS: dict[str, tuple[type, ...]] = {
    "steps": (int,),
    "lr": (float, int),
    "batch_size": (int,),
    "seed": (int,),
    "threads": (int,),
    "val_every": (int,),
    "augment": (bool,),
    "appearance_swap": (float, int),
    "preprocessing": (str,),
    "w1": (float, int),
    "w2": (float, int),
    "w_consistency": (float, int),
}
#: How each stage runs rather than what it trains: they may change when a run is resumed.
RUN_KEYS = ("threads",)
COLLECT_KEYS: dict[str, tuple[type, ...]] = {
    "houses": (int,),
    "frames_per_house": (int,),
    "include_house": (list,),
    "include_house_frames": (int,),
    "frames": (int,),
    "seed": (int,),
    "noise": (float, int),
    "workers": (int,),
    "appearances": (int,),
}
_NAME = re.compile(r"^[A-Za-z0-9_]+$")


@dataclass
class Stage:
    """One training stage: its folder name under the run, the networks's options, and where it starts."""

    name: str
    options: dict[str, Any] = field(default_factory=dict)
    init: str | None = None  # an earlier VelocityNet stage's name


@dataclass
class Recipe:
    name: str
    preset: str
    data: str
    collect: dict[str, Any]
    viewnet: Stage
    velocitynet: list[Stage]
    int8: bool = True
    description: str = ""

    @property
    def houses(self) -> bool:
        """Whether the data is recorded across procedural houses (a folder of shards)."""
        return int(self.collect.get("houses", 0)) > 0

    def record(self) -> dict[str, Any]:
        """What the run folder records to tell whether a rerun is the same run (how stages run is left out)."""
        doc = asdict(self)
        for stage in [doc["viewnet"], *doc["velocitynet"]]:
            for key in RUN_KEYS:
                stage["options"].pop(key, None)
        for key in ("description", "int8"):
            doc.pop(key)
        doc["collect"] = {k: v for k, v in doc["collect"].items() if k != "workers"}
        return doc


def available() -> list[str]:
    return sorted(p.stem for p in RECIPES.glob("*.toml"))


def resolve(name_or_path: str) -> Path:
    """A recipe's file: NAME (training/recipes/NAME.toml) or a path to a .toml file."""
    if name_or_path.endswith(".toml") or "/" in name_or_path:
        path = Path(name_or_path)
    else:
        path = RECIPES / f"{name_or_path}.toml"
    if not path.is_file():
        raise ValueError(
            f"--recipe {name_or_path}: no such recipe (known: {', '.join(available())}, or a .toml file)"
        )
    return path


def _check(where: str, table: dict, keys: dict[str, tuple[type, ...]]) -> dict[str, Any]:
    for key, value in table.items():
        if key not in keys:
            raise ValueError(f"{where}: unknown key {key!r} (known: {', '.join(sorted(keys))})")
        if not isinstance(value, keys[key]) or (isinstance(value, bool) and bool not in keys[key]):
            raise ValueError(f"{where}: {key} = {value!r} is not {keys[key][0].__name__}")
    return dict(table)


def _stage(where: str, table: Any, default_name: str) -> Stage:
    if not isinstance(table, dict):
        raise ValueError(f"{where}: expected a table of stage options")
    table = dict(table)
    name = str(table.pop("name", default_name))
    init = table.pop("init", None)
    if default_name != "viewnet" and (not _NAME.match(name) or name in ("collect", "viewnet", "export")):
        raise ValueError(
            f"{where}: name {name!r} must be letters, digits or _, not collect, viewnet or export"
        )
    return Stage(name, _check(where, table, STAGE_KEYS), None if init is None else str(init))


def parse(doc: dict[str, Any], name: str) -> Recipe:
    where = f"recipe {name}"
    known = {"description", "preset", "data", "collect", "viewnet", "velocitynet", "export"}
    unknown = sorted(set(doc) - known)
    if unknown:
        raise ValueError(f"{where}: unknown key {unknown[0]!r} (known: {', '.join(sorted(known))})")
    from vtr.training.config import PRESETS

    preset = str(doc.get("preset", "default"))
    if preset not in PRESETS:
        raise ValueError(f"{where}: preset must be one of {sorted(PRESETS)}, got {preset!r}")
    collect = _check(f"{where} [collect]", doc.get("collect", {}), COLLECT_KEYS)
    viewnet = _stage(f"{where} [viewnet]", doc.get("viewnet", {}), "viewnet")
    viewnet.name = "viewnet"
    tables = doc.get("velocitynet", [{}])
    if not isinstance(tables, list) or not tables:
        raise ValueError(f"{where}: [[velocitynet]] must list at least one stage")
    stages: list[Stage] = []
    for i, table in enumerate(tables):
        stage = _stage(
            f"{where} [[velocitynet]] {i + 1}", table, "velocitynet" if i == 0 else f"velocitynet_{i + 1}"
        )
        names = [s.name for s in stages]
        if stage.name in names:
            raise ValueError(f"{where}: two VelocityNet stages are named {stage.name!r}")
        if stage.init is not None and stage.init not in names:
            raise ValueError(f"{where}: stage {stage.name} starts from {stage.init!r}, not an earlier stage")
        stages.append(stage)
    export = doc.get("export", {})
    if not isinstance(export, dict) or set(export) - {"int8"}:
        raise ValueError(f"{where}: [export] holds only int8 = true|false")
    default_data = "data/houses" if int(collect.get("houses", 0)) > 0 else "data/house.npz"
    return Recipe(
        name=name,
        preset=preset,
        data=str(doc.get("data", default_data)),
        collect=collect,
        viewnet=viewnet,
        velocitynet=stages,
        int8=bool(export.get("int8", True)),
        description=str(doc.get("description", "")),
    )


def load(name_or_path: str) -> Recipe:
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # Python 3.10: the same parser, the tomli package (a base dependency there)
        import tomli as tomllib
    path = resolve(name_or_path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as err:
        raise ValueError(f"recipe {path}: {err}") from None
    return parse(doc, path.stem)


def apply_overrides(recipe: Recipe, args: argparse.Namespace) -> Recipe:
    """The command line's settings over the recipe's (what the run folder then records)."""
    from vtr.training.config import PRESETS

    recipe.preset = args.preset or recipe.preset
    if recipe.preset not in PRESETS:
        raise ValueError(f"--preset must be one of {sorted(PRESETS)}, got {recipe.preset!r}")
    recipe.data = args.data or recipe.data
    if args.frames is not None:
        recipe.collect["frames_per_house" if recipe.houses else "frames"] = args.frames
    if args.no_int8:
        recipe.int8 = False
    common = {k: getattr(args, k) for k in ("lr", "batch_size", "seed", "threads", "val_every")}
    net = {k: getattr(args, k) for k in ("augment", "preprocessing", "w1", "w2")}
    for stage in [recipe.viewnet, *recipe.velocitynet]:
        is_view = stage is recipe.viewnet
        steps = args.viewnet_steps if is_view else args.velocitynet_steps
        changes = {**common, **({} if is_view else net), "steps": steps if steps is not None else args.steps}
        stage.options.update({k: v for k, v in changes.items() if v is not None})
    return recipe


def _first_difference(a: Any, b: Any, where: str = "") -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if a.get(key) != b.get(key):
                return _first_difference(a.get(key), b.get(key), f"{where}.{key}" if where else key)
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            if x != y:
                return _first_difference(x, y, f"{where}[{i}]")
    return f"{where}: {a!r} there, {b!r} now"


def claim_run_folder(out: Path, recipe: Recipe) -> None:
    """Record the recipe in the run folder, or check that the folder holds a run of this same recipe."""
    record, path = recipe.record(), out / RECORD
    if path.exists():
        held = json.loads(path.read_text())
        if held != record:
            raise ValueError(
                f"{out} holds a run of another recipe ({_first_difference(held, record)}); "
                "choose another --out or delete it"
            )
        return
    if out.exists() and any((out / name).exists() for name in ("viewnet", "export", "summary.json")):
        raise ValueError(f"{out} holds a run of an earlier release (no {RECORD}); choose another --out")
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, json.dumps(record, indent=1, sort_keys=True) + "\n")
