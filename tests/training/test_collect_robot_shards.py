"""`vtr collect --sim` grows a folder of shards: a checkpoint writes only its new frames, whatever the dataset's
size; a kill -9 loses at most the shard being written; old .npz datasets still load."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from vtr import cli
from vtr.runtime.contracts import CameraSpec
from vtr.runtime.hello import Hello
from vtr.runtime.protocol import Limits
from vtr.runtime.robot import Observation
from vtr.training.collect_robot import RobotCollectConfig, collect
from vtr.training.dataset import load_dataset, save_dataset, synthetic_dataset

ROOT = Path(__file__).resolve().parents[2]


class PlaneRobot:
    """Never collides; each frame differs (its pixels encode the step), so frames can be told apart."""

    def __init__(self, size: int = 16, on_step: object = None) -> None:
        self.size, self.t, self.on_step = size, 0, on_step

    def handshake(self) -> Hello:
        camera = CameraSpec(width=self.size, height=self.size, fov_deg=None, height_m=None)
        return Hello("s", 0.0, 1, camera, Limits(v_max=0.5, w_max=1.0), dt=0.1, mode="lockstep", map="plane")

    def _obs(self) -> Observation:
        image = np.full((self.size, self.size, 3), self.t % 251, np.uint8)
        image[0, 0] = (self.t // 251) % 251
        return Observation(image, 0.1 * self.t, (0.01 * self.t, 0.0, 0.0), False)

    def reset(self, pose: object = None, seed: object = None) -> Observation:
        return self._obs()

    def observe(self) -> Observation:
        return self._obs()

    def step(self, v: float, w: float, duration: float) -> Observation:
        self.t += 1
        if callable(self.on_step):
            self.on_step()
        return self._obs()

    def stop(self) -> None:
        pass


def _files(root: Path) -> dict[str, tuple[int, int, int]]:
    """name -> (size, mtime_ns, inode): what changes when a file is written or replaced."""
    if not root.exists():
        return {}
    if root.is_file():  # one file for the whole dataset (the layout before shards)
        return {root.name: (root.stat().st_size, root.stat().st_mtime_ns, root.stat().st_ino)}
    return {e.name: (e.stat().st_size, e.stat().st_mtime_ns, e.stat().st_ino) for e in os.scandir(root)}


def test_a_checkpoint_writes_the_same_bytes_at_any_size_and_never_an_earlier_shard(tmp_path: Path) -> None:
    out = tmp_path / "d"
    checkpoints: list[tuple[int, set[str]]] = []  # (bytes written, files written) at each checkpoint
    seen = {"files": _files(out)}

    def watch() -> None:  # after every step: which files changed since the step before
        now = _files(out)
        written = {n for n, s in now.items() if seen["files"].get(n) != s}
        if written:
            checkpoints.append((sum(now[n][0] for n in written), written))
        seen["files"] = now

    cfg = RobotCollectConfig(
        sim="tcp://127.0.0.1:9", out=str(out), frames=6000, save_every=100, progress=False
    )
    collect(cfg, PlaneRobot(on_step=watch))
    assert len(checkpoints) >= 25
    shard_bytes = [b for b, _ in checkpoints]
    first, last = np.median(shard_bytes[:5]), np.median(shard_bytes[-5:])
    # A checkpoint writes 100-300 frames of 16x16 (an episode ends the shard), never the frames before:
    # the last ones write no more than the first ones (with the old single file, the 25th wrote 25x the 1st).
    assert last < 1.3 * first and max(shard_bytes) < 300 * 16 * 16 * 3 * 1.2
    for _, written in checkpoints:  # each one: its own four shard files and the index, nothing else
        assert "index.json" in written and len(written) == 5, written
    data = load_dataset(out)
    assert len(data) == 6000 and data.meta["source"] == "vtr collect --sim"
    np.testing.assert_array_equal(data.images[:][:, 1, 1, 0], np.arange(6000) % 251)  # every frame, in order
    ends = np.flatnonzero(np.diff(data.episodes)) + 1  # a shard boundary is an episode boundary
    assert np.all(data.commands[ends - 1] == 0.0) and tuple(data.commands[-1]) == (0.0, 0.0)


_CRASH = """
import os, signal, sys
sys.path.insert(0, {tests!r})
from test_collect_robot_shards import PlaneRobot
from vtr.training import shards
from vtr.training.collect_robot import RobotCollectConfig, collect

mode, steps = {mode!r}, {{"n": 0}}
def on_step():
    steps["n"] += 1
    if mode == "between" and steps["n"] == 730:
        os.kill(os.getpid(), signal.SIGKILL)
if mode == "writing":  # killed on the 4th checkpoint: its shard files are written, the index not yet
    calls, write_index = {{"n": 0}}, shards.write_index
    def dying_index(*args, **kw):
        calls["n"] += 1
        if calls["n"] == 4:
            os.kill(os.getpid(), signal.SIGKILL)
        write_index(*args, **kw)
    shards.write_index = dying_index
cfg = RobotCollectConfig(sim="tcp://127.0.0.1:9", out={out!r}, frames=2000, save_every=100, progress=False)
collect(cfg, PlaneRobot(on_step=on_step))
"""


@pytest.mark.parametrize("mode", ["between", "writing"])
def test_a_killed_collection_resumes_losing_at_most_the_shard_being_written(
    tmp_path: Path, mode: str
) -> None:
    out = tmp_path / "d"
    script = _CRASH.format(tests=str(Path(__file__).parent), mode=mode, out=str(out))
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(script)], cwd=ROOT, capture_output=True)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()[-2000:]
    before = load_dataset(out)  # what the index names is whole
    assert 300 <= len(before) <= 730 and len(before.images[:]) == len(before)
    summary = collect(
        RobotCollectConfig(
            sim="tcp://127.0.0.1:9", out=str(out), frames=2000, save_every=100, progress=False
        ),
        PlaneRobot(),
    )
    after = load_dataset(out)
    assert summary["added"] == 2000 - len(before) and len(after) == 2000
    np.testing.assert_array_equal(after.images[: len(before)], before.images[:])
    assert after.episodes[len(before)] == before.episodes.max() + 1
    assert not [n for n in os.listdir(out) if n.startswith(".")]  # the dead writer's temporary files are gone


def test_old_npz_datasets_still_load_and_sim_asks_for_a_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    old = tmp_path / "old.npz"
    save_dataset(old, synthetic_dataset(frames=64, size=16))
    assert len(load_dataset(old, image_size=16)) == 64
    code = cli.main(["collect", "--sim", "tcp://127.0.0.1:9", "--out", str(old), "--frames", "300"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "a dataset folder" in err and f"--out {tmp_path / 'old'}" in err and "still trains" in err
    assert len(load_dataset(old)) == 64  # untouched


def test_a_folder_that_is_not_a_dataset_is_refused(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    cfg = RobotCollectConfig(sim="tcp://127.0.0.1:9", out=str(tmp_path), frames=300, progress=False)
    with pytest.raises(ValueError, match="holds no dataset"):
        collect(cfg, PlaneRobot())
