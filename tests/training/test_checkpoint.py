"""Checkpoints hold tensors and plain data only, and are read without unpickling arbitrary objects."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from vtr.training import config, models
from vtr.training.checkpoint import CheckpointError, load_model, read_checkpoint, save_checkpoint

MARKER = "vtr-checkpoint-payload-ran"


class Payload:
    """Unpickling this would create a file: proof that code ran."""

    def __init__(self, target: Path) -> None:
        self.target = target

    def __reduce__(self):
        return (Path.touch, (self.target,))


def test_a_crafted_pickle_is_refused_without_running_its_code(tmp_path: Path) -> None:
    target = tmp_path / MARKER
    evil = tmp_path / "model.pt"
    torch.save({"kind": "velocitynet", "state_dict": {}, "x": Payload(target)}, evil)
    with pytest.raises(CheckpointError, match="refusing it"):
        read_checkpoint(evil)
    with pytest.raises(CheckpointError):
        load_model(tmp_path)  # a folder means its model.pt
    assert not target.exists()


def test_garbage_is_a_checkpoint_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x00not a checkpoint" * 10)
    with pytest.raises(CheckpointError, match="not a torch checkpoint"):
        read_checkpoint(bad)
    with pytest.raises(FileNotFoundError):
        read_checkpoint(tmp_path / "missing.pt")


def test_saved_checkpoints_are_plain_and_load_back(tmp_path: Path) -> None:
    cfg = config.VelocityNetConfig(image_size=32, channels=(4, 4, 8, 8, 8, 8, 8))
    net = models.VelocityNet(cfg)
    path = tmp_path / "model.pt"
    extra = {
        "mean_command": np.array([0.1, 0.2], np.float32),
        "step": np.int64(3),
        "meta": {"dt": np.float64(0.1)},
    }
    save_checkpoint(
        {"kind": "velocitynet", "model_config": config.to_dict(cfg), "state_dict": net.state_dict(), **extra},
        path,
    )
    kind, loaded, ckpt = load_model(path)
    assert kind == "velocitynet" and ckpt["step"] == 3 and ckpt["meta"] == {"dt": pytest.approx(0.1)}
    assert isinstance(ckpt["mean_command"], list)
    for k, v in net.state_dict().items():
        assert torch.equal(v, loaded.state_dict()[k])
    with pytest.raises(TypeError, match="plain data"):
        save_checkpoint({"bad": object()}, tmp_path / "x.pt")


def test_the_cli_refuses_a_crafted_checkpoint_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from vtr.cli import main

    target = tmp_path / MARKER
    evil = tmp_path / "evil.pt"
    torch.save({"kind": "velocitynet", "x": Payload(target)}, evil)
    assert main(["export", "--checkpoint", str(evil), "--out", str(tmp_path / "o.onnx")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "refusing it" in err and not target.exists()
    assert not (tmp_path / "o.onnx").exists()
