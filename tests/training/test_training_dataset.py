"""The dataset file: round trip, clear errors for corrupt or mismatched files, windows and splits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vtr.training.dataset import (
    DatasetError,
    FrameData,
    load_dataset,
    save_dataset,
    split_episodes,
    synthetic_dataset,
    window_starts,
)


@pytest.fixture
def saved(tmp_path: Path) -> tuple[Path, FrameData]:
    data = synthetic_dataset(frames=40, size=16, episodes=3, seed=1)
    path = tmp_path / "d.npz"
    save_dataset(path, data)
    return path, data


def test_round_trip_keeps_arrays_and_metadata(saved: tuple[Path, FrameData]) -> None:
    path, data = saved
    back = load_dataset(path, image_size=16)
    np.testing.assert_array_equal(back.images, data.images)
    np.testing.assert_array_equal(back.commands, data.commands)
    np.testing.assert_array_equal(back.episodes, data.episodes)
    assert back.meta["format_version"] == 1 and back.meta["map"] == "synthetic"
    assert not list(path.parent.glob("*.tmp"))


def test_truncated_file_is_a_clear_error(saved: tuple[Path, FrameData]) -> None:
    path, _ = saved
    blob = path.read_bytes()
    path.write_bytes(blob[: len(blob) // 2])
    with pytest.raises(DatasetError, match="corrupt"):
        load_dataset(path)


def test_missing_file_says_how_to_make_one(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="vtr collect"):
        load_dataset(tmp_path / "nope.npz")


def test_image_size_mismatch_names_both_sizes(saved: tuple[Path, FrameData]) -> None:
    path, _ = saved
    with pytest.raises(DatasetError, match="16x16 images but the model expects 128x128"):
        load_dataset(path, image_size=128)


def test_missing_array_and_wrong_version(tmp_path: Path, saved: tuple[Path, FrameData]) -> None:
    _, data = saved
    bad = tmp_path / "bad.npz"
    np.savez(bad, images=data.images)
    with pytest.raises(DatasetError, match="lacks arrays"):
        load_dataset(bad)
    np.savez(
        bad,
        images=data.images,
        commands=data.commands,
        poses=data.poses,
        episodes=data.episodes,
        meta=np.array('{"format_version": 99}'),
    )
    with pytest.raises(DatasetError, match="format version 99"):
        load_dataset(bad)


def test_inconsistent_arrays_are_rejected_before_saving(
    saved: tuple[Path, FrameData], tmp_path: Path
) -> None:
    _, data = saved
    data.commands = data.commands[:-1]
    with pytest.raises(DatasetError, match="commands has shape"):
        save_dataset(tmp_path / "x.npz", data)


def test_windows_never_cross_episodes() -> None:
    episodes = np.array([0, 0, 0, 1, 1, 2, 2, 2, 2])
    np.testing.assert_array_equal(window_starts(episodes, 2), [0, 1, 3, 5, 6, 7])
    np.testing.assert_array_equal(window_starts(episodes, 3), [0, 5, 6])
    np.testing.assert_array_equal(window_starts(episodes, 3, allowed=np.array([2])), [5, 6])


def test_validation_split_holds_out_whole_episodes() -> None:
    episodes = np.repeat(np.arange(20), 10)
    train, val = split_episodes(episodes, 0.2, seed=3)
    assert len(val) == 4 and len(np.intersect1d(train, val)) == 0
    assert len(train) + len(val) == 20
    again = split_episodes(episodes, 0.2, seed=3)
    np.testing.assert_array_equal(again[1], val)
    with pytest.raises(DatasetError, match="at least 2 episodes"):
        split_episodes(np.zeros(5, int), 0.2, 0)


def test_a_dataset_that_expands_far_beyond_its_size_is_refused_unread(tmp_path: Path) -> None:
    """A compressed archive of zeros (a zip bomb) is refused from its headers, before np.load allocates."""
    import resource

    bomb = tmp_path / "bomb.npz"
    np.savez_compressed(bomb, images=np.zeros((2000, 128, 128, 3), np.uint8))  # ~98 MB of zeros in ~0.1 MB
    assert bomb.stat().st_size < 2_000_000
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(DatasetError, match="refused"):
        load_dataset(bomb)
    grown_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before
    assert grown_kb < 50_000  # far less than the 98 MB the arrays would take


def test_saved_datasets_load_within_the_expansion_cap(saved: tuple[Path, FrameData]) -> None:
    from vtr.runtime.npz_guard import MAX_EXPANSION, check_npz

    path, _ = saved
    assert check_npz(path) <= MAX_EXPANSION * path.stat().st_size
