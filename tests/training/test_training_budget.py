"""--max-minutes: a training stops on its wall-time budget and still finishes like a complete one."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from vtr.training.checkpoint import read_checkpoint
from vtr.training.config import TrainConfig, get_preset
from vtr.training.dataset import save_dataset, synthetic_dataset
from vtr.training.train import train_viewnet


def test_a_spent_budget_stops_early_and_still_saves_the_model_and_report(tmp_path: Path) -> None:
    preset = get_preset("tiny")
    data = tmp_path / "d.npz"
    save_dataset(data, synthetic_dataset(frames=64, size=32))
    cfg = replace(preset.train_viewnet, steps=500, log_every=2, val_every=1000, max_minutes=1e-9)
    train_viewnet(data, tmp_path / "v", preset.viewnet, cfg)
    rows = [json.loads(line) for line in (tmp_path / "v" / "metrics.jsonl").read_text().splitlines()]
    budget = [r for r in rows if r["split"] == "budget"]
    assert budget and budget[0]["step"] == 2  # the first log interval past the (already spent) budget
    assert max(r["step"] for r in rows) == 2  # nothing trained after it
    assert any(r["split"] == "val" and r["step"] == 2 for r in rows)
    assert (tmp_path / "v" / "model.pt").is_file() and (tmp_path / "v" / "report.json").is_file()
    ckpt = read_checkpoint(tmp_path / "v" / "model.pt")
    # the model says where it stopped and what it was trained on, not what was asked
    assert ckpt["steps_done"] == 2 and ckpt["train_config"]["steps"] == 500
    assert ckpt["data_meta"]["frames"] == 64


def test_a_negative_or_nan_budget_is_refused() -> None:
    for bad in (-1.0, float("nan")):
        with pytest.raises(ValueError, match="max_minutes"):
            TrainConfig(max_minutes=bad)
