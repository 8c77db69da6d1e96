"""studies/ stays out of the installed package: pyproject never names it, and no library imports it."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
LIBRARIES = ("runtime", "sim2d", "training", "export", "benchmarks", "evaluation", "models", "vtr")


def test_pyproject_does_not_install_the_studies() -> None:
    # packages are listed one by one (no find:), so a folder it never names is never installed
    text = (ROOT / "pyproject.toml").read_text()
    assert "packages = [" in text and "studies" not in text


def test_no_library_imports_a_study() -> None:
    for folder in LIBRARIES:
        for path in (ROOT / folder).glob("*.py"):
            text = path.read_text()
            assert "from studies" not in text and "import studies" not in text, path
