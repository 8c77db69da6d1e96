"""The shipped models, installed with the package as ``vtr.models`` (package data), so that `vtr demo`,
`vtr eval` and `vtr bench latency` find them from any directory and from an installed copy alike."""

from __future__ import annotations

from pathlib import Path

MODELS_DIR = Path(__file__).resolve().parent
VELOCITYNET = "velocitynet.onnx"


def find_model(explicit: str | Path | None = None, name: str = VELOCITYNET) -> Path:
    """``explicit`` if given (it must exist), else ``models/<name>`` in the working directory, else the
    shipped one. FileNotFoundError names where it looked and what to do."""
    if explicit is not None:
        path = Path(explicit)
        if path.is_dir():
            raise IsADirectoryError(f"{path} is a folder, not a model file; pass the .onnx file itself")
        if not path.is_file():
            raise FileNotFoundError(f"model file not found: {path}")
        return path
    for candidate in (Path.cwd() / "models" / name, MODELS_DIR / name):
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(
        f"no models/{name} here or in {MODELS_DIR}; pass --model, or train and export one (`vtr train all`)"
    )


def int8_path(model: str | Path) -> Path:
    """Where a model's int8 twin lives: ``<stem>-int8<suffix>`` beside it."""
    model = Path(model)
    return model.with_name(model.stem + "-int8" + model.suffix)


def find_int8(model: Path, explicit: str | Path | None = None) -> Path | None:
    """``explicit`` if given (it must exist), else the int8 twin beside ``model`` if there is one, else None."""
    if explicit is not None:
        if Path(explicit).is_dir():
            raise IsADirectoryError(
                f"{explicit} is a folder, not an int8 model file; pass the .onnx file itself"
            )
        if not Path(explicit).is_file():
            raise FileNotFoundError(f"int8 model not found: {explicit}")
        return Path(explicit)
    twin = int8_path(model)
    return twin if twin.is_file() else None
