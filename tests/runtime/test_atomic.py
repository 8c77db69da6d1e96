"""Atomic writes: the target is replaced whole or not at all."""

from __future__ import annotations

from pathlib import Path

import pytest

from vtr.runtime.atomic import atomic_path, write_bytes_atomic, write_text_atomic


def test_atomic_write_replaces_the_target_and_leaves_no_temporary(tmp_path: Path) -> None:
    target = tmp_path / "sub" / "out.json"
    write_text_atomic(target, "one")
    write_text_atomic(target, "two")
    assert target.read_text() == "two"
    write_bytes_atomic(tmp_path / "b.bin", b"\x00\x01")
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["b.bin", "out.json", "sub"]


def test_a_failed_write_keeps_the_old_file_and_cleans_up(tmp_path: Path) -> None:
    target = tmp_path / "model.onnx"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".onnx"
        tmp.write_text("half")
        raise RuntimeError("crash mid-write")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["model.onnx"]


WRITER = """
import sys, time
from vtr.runtime.atomic import atomic_path, temp_dir
with atomic_path(sys.argv[1] + "/model.onnx") as tmp, temp_dir(sys.argv[1]) as scratch:
    tmp.write_text("half")
    (scratch / "raw.onnx").write_text("raw")
    print("writing", flush=True)
    time.sleep(60)
"""


def _writer(folder: Path):
    import os
    import subprocess
    import sys

    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    proc = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(folder)], stdout=subprocess.PIPE, env=env, text=True
    )
    assert proc.stdout.readline().strip() == "writing"
    return proc


def test_leftovers_of_a_killed_writer_are_removed_by_the_next_write_but_a_live_writer_is_left_alone(tmp_path):
    dead, live = _writer(tmp_path), _writer(tmp_path)
    dead.kill()
    dead.wait()
    assert len(list(tmp_path.iterdir())) == 4  # two temporary files, two scratch folders
    write_text_atomic(tmp_path / "other.json", "{}")
    names = sorted(p.name for p in tmp_path.iterdir())
    assert len(names) == 3 and "other.json" in names
    assert all(str(live.pid) in n for n in names if n != "other.json")  # only the live writer's remain
    live.kill()
    live.wait()
