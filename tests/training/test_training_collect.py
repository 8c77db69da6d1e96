"""`vtr collect` on a tiny budget: the file, its metadata, and that each command really links its pair."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from vtr.training.collect import arc_points
from vtr.training.config import CollectConfig
from vtr.training.dataset import load_dataset

pytest.importorskip("pymunk")
pytest.importorskip("vtr.sim2d.simulator")  # the simulator lands from its own branch


@pytest.fixture(scope="module")
def collected(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    from vtr.training.collect import run

    out = tmp_path_factory.mktemp("collect") / "tiny.npz"
    cfg = CollectConfig(
        out=str(out), frames=150, seed=3, image_size=32, episode_min=20, episode_max=40, progress=False
    )
    return out, run(cfg)


def test_dataset_has_metadata_and_episodes(collected: tuple[Path, dict]) -> None:
    path, summary = collected
    data = load_dataset(path, image_size=32)
    assert len(data) == 150 and summary["frames"] == 150
    assert data.meta["dt"] == 0.1 and data.meta["seed"] == 3 and data.meta["map"]
    assert data.meta["camera"]["width"] == 32
    assert len(np.unique(data.episodes)) >= 4
    assert np.abs(data.commands[:, 0]).max() <= 0.5 and np.abs(data.commands[:, 1]).max() <= 1.0
    last = np.r_[data.episodes[1:] != data.episodes[:-1], True]
    assert np.all(data.commands[last] == 0)  # the last frame of an episode links to nothing


def test_each_command_moves_its_frame_to_the_next(collected: tuple[Path, dict]) -> None:
    data = load_dataset(collected[0])
    checked = 0
    for t in range(len(data) - 1):
        if data.episodes[t] != data.episodes[t + 1]:
            continue
        x, y, yaw = (float(c) for c in data.poses[t])
        v, w = (float(c) for c in data.commands[t])
        px, py = arc_points(x, y, yaw, v, w, 0.1, samples=1)[0]
        assert math.hypot(px - data.poses[t + 1, 0], py - data.poses[t + 1, 1]) < 0.01
        dyaw = (data.poses[t + 1, 2] - yaw - w * 0.1 + math.pi) % (2 * math.pi) - math.pi
        assert abs(dyaw) < 0.01
        checked += 1
    assert checked > 100


def test_driving_covers_every_kind_of_motion(collected: tuple[Path, dict]) -> None:
    data = load_dataset(collected[0])
    v, w = data.commands[:, 0], data.commands[:, 1]
    assert np.any((v > 0) & (w == 0)), "pure translation"
    assert np.any((v == 0) & (w > 0)) and np.any((v == 0) & (w < 0)), "pure rotation both ways"
    assert np.any((v != 0) & (w != 0)), "combined motion"


def test_same_seed_same_dataset(collected: tuple[Path, dict], tmp_path: Path) -> None:
    from vtr.training.collect import run

    out = tmp_path / "again.npz"
    run(
        CollectConfig(
            out=str(out), frames=150, seed=3, image_size=32, episode_min=20, episode_max=40, progress=False
        )
    )
    a, b = load_dataset(collected[0]), load_dataset(out)
    np.testing.assert_array_equal(a.images, b.images)
    np.testing.assert_array_equal(a.commands, b.commands)


def test_collect_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from vtr import cli
    from vtr.training.collect import MIN_FRAMES

    out = tmp_path / "c.npz"
    frames = str(
        MIN_FRAMES
    )  # the fewest frames training accepts (fewer is refused: tests/test_cli_bad_input.py)
    args = [
        "collect",
        "--out",
        str(out),
        "--frames",
        frames,
        "--image-size",
        "32",
        "--no-progress",
        "--noise",
    ]
    assert cli.main(args) == 0
    assert load_dataset(out).meta["noise"] == 0.05
    assert f'"frames": {frames}' in capsys.readouterr().out
    # ... and it can be trained on: validation episodes held out, N + 1 frame windows on both sides
    from vtr.training.config import MPCLossConfig, TrainConfig
    from vtr.training.dataset import split_episodes, window_starts

    data = load_dataset(out)
    for ids in split_episodes(data.episodes, TrainConfig().val_fraction, TrainConfig().seed):
        assert len(window_starts(data.episodes, MPCLossConfig().horizon + 1, ids)) > 0
