"""A repeat's outputs (--log, --mcap, --foxglove): checked before any is created, all removed when the start
fails on one of them, and a full disk mid-run leaves whole lines and a message naming the file."""

from __future__ import annotations

import errno
import io
import json
import socket
from pathlib import Path

import numpy as np
import pytest
from runtime_fakes import FakeSim, build_velocitynet_onnx, corridor_route

from vtr.runtime import run_outputs
from vtr.runtime.run_log import JsonLinesLog, LogWriteError
from vtr.runtime.run_outputs import RunOutputs, check_outputs
from vtr.sim2d.server import ServerThread

IMAGES = np.zeros((3, 4, 4, 3), np.uint8)


class FullDisk(io.FileIO):
    """A file on a disk with ``room`` bytes left: a write takes what fits, the next raises ENOSPC."""

    def __init__(self, path: Path, room: int) -> None:
        super().__init__(path, "w")
        self.room = room

    def write(self, data: bytes) -> int:
        if self.room <= 0:
            raise OSError(errno.ENOSPC, "No space left on device")
        written = super().write(bytes(data[: self.room]))
        self.room -= written
        return written


def test_a_full_disk_cuts_the_log_back_to_whole_lines_and_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "run.jsonl"
    log = JsonLinesLog(path, stream=FullDisk(path, room=50))
    log.write({"step": 0, "v": 0.1})
    log.write({"step": 1, "v": 0.1})
    with pytest.raises(
        LogWriteError, match=rf"cannot write the log {path}: No space left on device.* 2 whole"
    ):
        for step in range(2, 10):
            log.write({"step": step, "v": 0.1})
    log.close()
    lines = path.read_text().splitlines(keepends=True)
    assert len(lines) == 2 and all(line.endswith("\n") and json.loads(line) for line in lines)


def test_outputs_are_checked_before_any_is_created(tmp_path: Path) -> None:
    afile = tmp_path / "a.txt"
    afile.write_text("x")
    for log, mcap, words in [
        (str(tmp_path), None, "--log .* is a folder"),
        (str(afile / "run.jsonl"), None, "is a file, not a folder"),
        (None, str(afile), "--mcap .*a file is in the way"),
        (str(tmp_path / "same.mcap"), str(tmp_path / "same.mcap"), "the same file"),
    ]:
        with pytest.raises(ValueError, match=words):
            check_outputs(log, mcap)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]


def test_a_start_failing_on_one_output_removes_the_others_and_their_folders(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def refuse(path: str) -> None:
        raise OSError(f"cannot open {path}")

    monkeypatch.setattr(run_outputs, "JsonLinesLog", refuse)  # the log fails after the MCAP was opened
    with pytest.raises(OSError, match="cannot open"):
        RunOutputs(IMAGES, log=str(tmp_path / "logs/run.jsonl"), mcap=str(tmp_path / "bags/new/run.mcap"))
    assert list(tmp_path.iterdir()) == []


def test_a_busy_foxglove_port_is_one_line_and_leaves_nothing(tmp_path: Path) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(OSError, match=rf"--foxglove {port}: .*in use.*pick a free port"):
            RunOutputs(
                IMAGES, log=str(tmp_path / "run.jsonl"), mcap=str(tmp_path / "run.mcap"), foxglove_port=port
            )
    assert list(tmp_path.iterdir()) == []


@pytest.fixture(scope="module")
def taught(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, str]:
    folder = tmp_path_factory.mktemp("taught")
    route = folder / "route.npz"
    corridor_route().save(route)
    return build_velocitynet_onnx(str(folder / "tiny.onnx")), str(route)


def _repeat(endpoint: str, taught: tuple[str, str], *more: str) -> list[str]:
    model, route = taught
    return ["repeat", "--sim", endpoint, "--model", model, "--route", route, "--profile", "paper", *more]


def test_a_full_disk_mid_run_fails_the_run_in_one_line_naming_the_log(
    tmp_path: Path,
    taught: tuple[str, str],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    from vtr.cli import main

    monkeypatch.setattr(run_outputs, "JsonLinesLog", lambda p: JsonLinesLog(p, stream=FullDisk(Path(p), 900)))
    log = tmp_path / "run.jsonl"
    sim = FakeSim()
    with ServerThread(sim) as server:
        assert main(_repeat(server.endpoint, taught, "--log", str(log))) == 1
    err = capsys.readouterr().err  # after the notes on the fake camera: the one line
    line = err.strip().splitlines()[-1]
    assert "Traceback" not in err and line.startswith("vtr repeat: cannot write the log")
    assert f"cannot write the log {log}: No space left on device" in line
    assert all(json.loads(text) for text in log.read_text().splitlines())  # no torn line
    assert log.read_text().endswith("\n")


def test_the_log_creates_its_folder_as_the_mcap_does(
    tmp_path: Path, taught: tuple[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    from vtr.cli import main

    log, mcap = tmp_path / "missing/dir/run.jsonl", tmp_path / "other/run.mcap"
    with ServerThread(FakeSim()) as server:
        assert main(_repeat(server.endpoint, taught, "--log", str(log), "--mcap", str(mcap))) == 0
    assert "summary" in log.read_text().splitlines()[-1] and mcap.stat().st_size > 0
