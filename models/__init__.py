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
        if not path.is_file():
            raise FileNotFoundError(f"model file not found: {path}")
        return path
    for candidate in (Path.cwd() / "models" / name, MODELS_DIR / name):
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(
        f"no models/{name} here or in {MODELS_DIR}; pass --model, or train and export one (`vtr train all`)"
    )
