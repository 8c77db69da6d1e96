"""Smoke test of the ViewNet command-path study: tiny preset, synthetic frames, a few steps."""

from __future__ import annotations

from pathlib import Path

from studies import viewnet_command_path as study
from vtr.training.dataset import save_dataset, synthetic_dataset


def test_it_measures_the_ratio_and_how_much_flow_the_command_moves(tmp_path: Path) -> None:
    data = tmp_path / "syn.npz"
    save_dataset(data, synthetic_dataset(frames=80, size=32, episodes=4, seed=0))
    tiny = ["--data", str(data), "--preset", "tiny", "--steps", "2", "--every", "1", "--val-batches", "2"]
    rows = study.measure(study.parser().parse_args([*tiny, "--velocity-gain", "10", "--head-init", "0.1"]))
    assert [r["step"] for r in rows] == [1, 2]
    assert all(0.5 < r["ratio_to_copy"] < 2 for r in rows)
    assert all(0 < r["flow_from_command"] <= 2 * r["flow"] for r in rows)  # a non-zero head sees the command
