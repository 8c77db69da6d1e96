"""The online-MPC baseline: searches velocities with a (tiny) ViewNet and returns VelocityNet's output shape."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
models = pytest.importorskip("vtr.training.models")
config = pytest.importorskip("vtr.training.config")


def _zero_viewnet(path: Path) -> Path:
    cfg = config.ViewNetConfig(
        image_size=32, encoder_channels=(4, 4, 8, 8, 8, 8, 8, 16), decoder_channels=(8, 4), flow_resolution=16
    )
    net = models.ViewNet(cfg)
    with torch.no_grad():
        # zero flow for every command: the prediction is the input image
        for p in net.parameters():
            p.zero_()
    torch.save({"kind": "viewnet", "model_config": config.to_dict(cfg), "state_dict": net.state_dict()}, path)
    return path


def test_mpc_returns_bounded_plan(tmp_path: Path) -> None:
    from vtr.evaluation.mpc import ViewNetMPC

    ckpt = _zero_viewnet(tmp_path / "viewnet.pt")
    mpc = ViewNetMPC(ckpt, horizon=2, samples=8, iterations=2, threads=1, seed=0)
    rng = np.random.default_rng(0)
    cur = rng.integers(0, 256, (32, 32, 3), dtype=np.uint8)
    goal = rng.integers(0, 256, (32, 32, 3), dtype=np.uint8)
    plan = mpc.predict(cur, goal)
    assert plan.shape == (2, 2) and plan.dtype == np.float32
    assert np.all(np.abs(plan[0]) <= 0.5) and np.all(np.abs(plan[1]) <= 1.0)
    # an all-zero ViewNet predicts the input for every command: all costs tie, and the first candidate
    # (the warm-start mean, zero at the first call) wins
    np.testing.assert_array_equal(plan, np.zeros((2, 2), dtype=np.float32))


def test_mpc_rejects_a_velocitynet_checkpoint(tmp_path: Path) -> None:
    from vtr.evaluation.mpc import ViewNetMPC

    cfg = config.VelocityNetConfig(image_size=32, channels=(4, 4, 8, 8, 8, 8, 8))
    path = tmp_path / "vel.pt"
    torch.save(
        {
            "kind": "velocitynet",
            "model_config": config.to_dict(cfg),
            "state_dict": models.VelocityNet(cfg).state_dict(),
        },
        path,
    )
    with pytest.raises(ValueError, match="not a viewnet"):
        ViewNetMPC(path, horizon=2, samples=8, iterations=1, threads=1, seed=0)
