"""`vtr collect --houses`: parallel workers write per-house shards that open memory-mapped, lazily."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from vtr.training.collect import arc_points
from vtr.training.collect_houses import HousesConfig, parse_seed_range, run_houses
from vtr.training.config import CollectConfig
from vtr.training.dataset import DatasetError
from vtr.training.shards import ShardedImages, load_sharded

SMALL = CollectConfig(
    image_size=32, episode_min=20, episode_max=40, mix="repeat", reverse_fraction=0.2, progress=False
)


@pytest.fixture(scope="module")
def sharded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("houses") / "ds"
    cfg = HousesConfig(out=str(out), seeds=(3, 4, 5), frames_per_house=120, workers=2, collect=SMALL)
    return out, run_houses(cfg, progress=False)


def test_index_shards_and_house_ids(sharded: tuple[Path, dict]) -> None:
    out, summary = sharded
    assert summary["frames"] == 360 and summary["houses"] == 3 and summary["frames_per_s"] > 0
    data = load_sharded(out, image_size=32)
    assert len(data) == 360 and isinstance(data.images, ShardedImages)
    assert data.house_names == ["random:3", "random:4", "random:5"]
    assert np.array_equal(np.bincount(data.houses), [120, 120, 120])
    # Episodes are global, contiguous, and never span two houses.
    assert np.all(np.diff(data.episodes) >= 0)
    for e in np.unique(data.episodes):
        assert len(np.unique(data.houses[data.episodes == e])) == 1
    index = json.loads((out / "index.json").read_text())
    assert index["meta"]["house_seeds"] == [3, 4, 5]


def test_commands_link_frames_in_every_house(sharded: tuple[Path, dict]) -> None:
    data = load_sharded(sharded[0])
    same = np.flatnonzero(data.episodes[1:] == data.episodes[:-1])  # pairs (t, t + 1) in one episode
    pairs = np.concatenate([data.poses[same], data.commands[same]], axis=1).astype(np.float64)
    ends = np.array([arc_points(*row, 0.1, samples=1)[0] for row in pairs])
    assert len(same) > 300
    assert np.hypot(*(ends - data.poses[same + 1, :2]).T).max() < 0.01


def test_lazy_images_match_the_shard_files(sharded: tuple[Path, dict]) -> None:
    out = sharded[0]
    data = load_sharded(out)
    second = np.load(out / "house_0000004_0.images.npy", allow_pickle=False)
    idx = np.array([[125, 121], [359, 0]])
    got = data.images[idx]
    assert got.shape == (2, 2, 32, 32, 3)
    np.testing.assert_array_equal(got[0, 0], second[5])
    np.testing.assert_array_equal(got[0, 1], second[1])
    np.testing.assert_array_equal(data.images[-1], data.images[359])
    assert data.images[10:13].shape == (3, 32, 32, 3)
    with pytest.raises(IndexError):
        data.images[np.array([360])]


def test_same_seeds_same_data_whatever_the_worker_count(sharded: tuple[Path, dict], tmp_path: Path) -> None:
    cfg = HousesConfig(
        out=str(tmp_path / "again"), seeds=(4,), frames_per_house=120, workers=1, collect=SMALL
    )
    run_houses(cfg, progress=False)
    a = np.load(sharded[0] / "house_0000004_0.images.npy")
    b = np.load(tmp_path / "again" / "house_0000004_0.images.npy")
    np.testing.assert_array_equal(a, b)


def test_repeat_mix_drives_creeping_fast_arcs_reverse_and_both_turns(sharded: tuple[Path, dict]) -> None:
    data = load_sharded(sharded[0])
    v, w = data.commands[:, 0], data.commands[:, 1]
    assert np.any((v > 0) & (v < 0.08)), "creeping"
    assert np.any((np.abs(v) > 0.35) & (np.abs(w) >= 0.5)), "fast arcs"
    assert np.any(v < 0), "reverse"
    assert np.any((v == 0) & (w > 0)) and np.any((v == 0) & (w < 0)), "turns in place both ways"


def test_broken_or_unfinished_datasets_are_clear_errors(sharded: tuple[Path, dict], tmp_path: Path) -> None:
    (tmp_path / "index.json").write_text('{"format": "vtr-shards", "format_version": 1, "shards": []}')
    with pytest.raises(DatasetError, match="no shards"):
        load_sharded(tmp_path)
    doc = json.loads((sharded[0] / "index.json").read_text())
    doc["shards"][0]["name"] = "missing"
    (tmp_path / "index.json").write_text(json.dumps(doc))
    with pytest.raises(DatasetError, match="missing or corrupt"):
        load_sharded(tmp_path)


def test_seed_range_parsing() -> None:
    assert parse_seed_range("3:6") == [3, 4, 5] and parse_seed_range("7") == [7]
    for bad in ("a:b", "5:5", "-1:3", "6:2"):
        with pytest.raises(ValueError, match="house-seeds"):
            parse_seed_range(bad)


def test_named_maps_join_the_procedural_houses(tmp_path: Path) -> None:
    cfg = HousesConfig(
        out=str(tmp_path / "mixed"),
        seeds=(3,),
        frames_per_house=40,
        workers=1,
        collect=SMALL,
        named=("house",),
        named_frames=60,
    )
    summary = run_houses(cfg, progress=False)
    data = load_sharded(tmp_path / "mixed", image_size=32)
    assert summary["frames"] == 100 and summary["houses"] == 2
    assert sorted(data.house_names) == ["house", "random:3"]
    counts = dict(zip(data.house_names, np.bincount(data.houses).tolist(), strict=True))
    assert counts == {"house": 60, "random:3": 40}
    with pytest.raises(ValueError, match="named_frames"):
        HousesConfig(named=("house",), named_frames=1)
