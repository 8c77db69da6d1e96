"""The floor lease's script, dry run at the tiny preset on the CPU: it collects two appearances, trains the
candidates it is asked for and packs each run's model and report."""

from __future__ import annotations

import tarfile
from pathlib import Path

import pytest

from studies import floors_on_gpu


@pytest.mark.slow
def test_tiny_dry_run_packs_the_candidates_it_trained(tmp_path: Path) -> None:
    out, work = tmp_path / "out", tmp_path / "work"
    argv = ["--out", str(out), "--work", str(work), "--tiny", "--device", "cpu", "--workers", "1"]
    assert floors_on_gpu.main([*argv, "--candidates", "swap", "--budget-s", "240"]) == 0
    assert (work / "data" / "floors").is_dir()
    with tarfile.open(work / "runs.tgz") as tar:
        names = set(tar.getnames())
    assert {"swap/model.pt", "swap/report.json"} <= names
    assert not any(n.startswith("plain/") for n in names)  # only the candidates asked for
    assert (out / "part_00").read_bytes() == (work / "runs.tgz").read_bytes()
