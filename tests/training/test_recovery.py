"""Recovery views: corrective labels with the right signs, views rendered where the labels say, training."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from vtr.runtime.contracts import V_MAX, W_MAX
from vtr.training.collect_houses import HousesConfig, run_houses
from vtr.training.config import CollectConfig, get_preset, override
from vtr.training.dataset import DatasetError, load_dataset, synthetic_dataset
from vtr.training.extra_pairs import JointCall
from vtr.training.recovery import RecoveryConfig, load_recovery, perturb, recovery_commands, render_recovery
from vtr.training.train import train_velocitynet, train_viewnet

CFG = RecoveryConfig()
FORWARD = np.array([[0.2, 0.0], [0.2, 0.0]])
REF = np.array([1.0, 2.0, 0.7])


def _label(offset: tuple[float, float, float], commands: np.ndarray = FORWARD) -> np.ndarray:
    return recovery_commands(perturb(REF, np.array(offset)), REF, commands, CFG)


def test_on_the_path_the_label_is_the_taught_command() -> None:
    np.testing.assert_allclose(_label((0.0, 0.0, 0.0)), FORWARD, atol=1e-7)


def test_labels_steer_back_to_the_path() -> None:
    assert _label((0.0, 0.05, 0.0))[0, 1] < 0  # left of the path, driving forward: turn right
    assert _label((0.0, -0.05, 0.0))[0, 1] > 0  # right of it: turn left
    assert _label((0.0, 0.0, 0.1))[0, 1] < 0  # yawed left: turn right
    assert _label((0.0, 0.0, -0.1))[0, 1] > 0
    assert _label((-0.03, 0.0, 0.0))[0, 0] > 0.2  # behind: faster
    assert _label((0.03, 0.0, 0.0))[0, 0] < 0.2  # ahead: slower
    # Reversing, the robot's rear leads: a left offset is corrected by turning the other way.
    assert _label((0.0, 0.05, 0.0), -FORWARD)[0, 1] > 0
    # In a turn in place the yaw error still gets a correction.
    assert _label((0.0, 0.0, 0.1), np.array([[0.0, 0.5], [0.0, 0.5]]))[0, 1] < 0.5


def test_labels_respect_the_limits() -> None:
    far = _label((-0.5, 0.5, 1.0), np.array([[V_MAX, W_MAX], [V_MAX, W_MAX]]))
    assert np.all(np.abs(far[:, 0]) <= V_MAX) and np.all(np.abs(far[:, 1]) <= W_MAX)


def test_config_refuses_bad_values() -> None:
    with pytest.raises(ValueError, match="per_window"):
        RecoveryConfig(per_window=0)
    with pytest.raises(ValueError, match="sigma_across"):
        RecoveryConfig(sigma_across=-1.0)


@pytest.fixture(scope="module")
def houses(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("rec") / "ds"
    small = CollectConfig(image_size=32, episode_min=20, episode_max=40, mix="repeat", progress=False)
    run_houses(
        HousesConfig(out=str(out), seeds=(3, 4), frames_per_house=100, workers=1, collect=small), False
    )
    return out


def test_zero_perturbation_renders_the_recorded_frames(houses: Path, tmp_path: Path) -> None:
    """With no perturbation the views are the dataset's own frames and the labels its own commands: the
    renderer, the house and the poses agree, so a perturbed view is what the robot would see there."""
    still = RecoveryConfig(per_window=0.5, sigma_along=0.0, sigma_across=0.0, sigma_yaw_deg=0.0)
    summary = render_recovery(houses, tmp_path / "r", still, workers=1, progress=False)
    data = load_dataset(houses)
    rec = load_recovery(tmp_path / "r", data)
    assert summary["views"] == len(rec) > 50 and summary["houses"] == 2
    views = np.asarray(rec.images[np.arange(len(rec))]).astype(int)
    # The same images but for a few texels: poses are stored as float32, and a ray that grazes a texture
    # edge can land on the next texel after that rounding.
    assert np.mean(views != data.images[rec.starts]) < 0.01
    taught = np.stack([data.commands[rec.starts], data.commands[rec.starts + 1]], axis=1)
    np.testing.assert_allclose(rec.commands, taught, atol=1e-6)
    assert np.all(data.episodes[rec.starts] == data.episodes[rec.starts + 2])  # whole windows


def test_perturbed_views_differ_and_carry_their_offsets(houses: Path, tmp_path: Path) -> None:
    render_recovery(houses, tmp_path / "r", RecoveryConfig(per_window=0.3, seed=1), workers=1, progress=False)
    data = load_dataset(houses)
    rec = load_recovery(tmp_path / "r", data)
    doc = json.loads((tmp_path / "r" / "recovery.json").read_text())
    offsets = np.concatenate([np.load(tmp_path / "r" / f"{p['name']}.offsets.npy") for p in doc["parts"]])
    assert len(offsets) == len(rec) and np.abs(offsets[:, 1]).max() <= 2.5 * CFG.sigma_across + 1e-6
    moved = np.abs(offsets).sum(axis=1) > 0.02
    views = np.asarray(rec.images[np.arange(len(rec))]).astype(int)
    assert np.mean(np.abs(views[moved] - data.images[rec.starts[moved]]).mean(axis=(1, 2, 3)) > 1) > 0.9
    for k in range(0, len(rec), 7):
        pose = perturb(data.poses[rec.starts[k]], offsets[k])
        want = recovery_commands(
            pose, data.poses[rec.starts[k]], data.commands[rec.starts[k] : rec.starts[k] + 2], CFG
        )
        np.testing.assert_allclose(rec.commands[k], want, atol=1e-5)


def test_variant_views_show_a_changed_world_with_the_taught_labels(houses: Path, tmp_path: Path) -> None:
    """Appearance variants: the same poses rendered with a re-seeded floor, so the views differ from the
    recorded frames while the labels stay the recorded commands."""
    cfg = RecoveryConfig(
        per_window=0.3,
        sigma_along=0.0,
        sigma_across=0.0,
        sigma_yaw_deg=0.0,
        variants=("retexture:floor={seed}",),
    )
    render_recovery(houses, tmp_path / "r", cfg, workers=1, progress=False)
    data = load_dataset(houses)
    rec = load_recovery(tmp_path / "r", data)
    views = np.asarray(rec.images[np.arange(len(rec))]).astype(int)
    changed = np.abs(views - data.images[rec.starts]).mean(axis=(1, 2, 3))
    assert np.mean(changed > 1.0) > 0.8  # the floor fills the lower half of almost every view
    taught = np.stack([data.commands[rec.starts], data.commands[rec.starts + 1]], axis=1)
    np.testing.assert_allclose(rec.commands, taught, atol=1e-6)


def test_recovery_views_of_another_dataset_are_refused(houses: Path, tmp_path: Path) -> None:
    render_recovery(houses, tmp_path / "r", RecoveryConfig(per_window=0.2), workers=1, progress=False)
    with pytest.raises(DatasetError, match="render them again"):
        load_recovery(tmp_path / "r", synthetic_dataset(frames=40, size=32, episodes=2, seed=0))
    with pytest.raises(DatasetError, match="recovery.json"):
        load_recovery(tmp_path / "nothing", load_dataset(houses))


def test_joint_call_splits_one_forward() -> None:
    calls = []

    def policy(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        calls.append(a.shape[0])
        return (a.mean(dim=(1, 2, 3)) - b.mean(dim=(1, 2, 3)))[:, None, None].expand(-1, 2, 2)

    joint = JointCall(policy, torch.ones(3, 3, 8, 8), torch.zeros(3, 3, 8, 8))
    out = joint(torch.zeros(5, 3, 8, 8), torch.zeros(5, 3, 8, 8))
    assert calls == [8] and out.shape == (5, 2, 2) and torch.all(out == 0) and torch.all(joint.extra == 1)


def test_training_with_recovery_views(houses: Path, tmp_path: Path) -> None:
    render_recovery(houses, tmp_path / "r", RecoveryConfig(per_window=0.3), workers=1, progress=False)
    preset = get_preset("tiny")
    train_viewnet(houses, tmp_path / "v", preset.viewnet, preset.train_viewnet)
    loss = override(preset.loss, w_recovery=0.5)
    train_velocitynet(
        houses,
        tmp_path / "v",
        tmp_path / "p",
        preset.velocitynet,
        loss,
        preset.train_velocitynet,
        recovery=tmp_path / "r",
    )
    ckpt = torch.load(tmp_path / "p" / "model.pt", weights_only=False)
    assert ckpt["recovery_views"] > 0 and ckpt["loss_config"]["w_recovery"] == 0.5
    with pytest.raises(ValueError, match="w_recovery is 0"):
        train_velocitynet(
            houses,
            tmp_path / "v",
            tmp_path / "q",
            preset.velocitynet,
            preset.loss,
            preset.train_velocitynet,
            recovery=tmp_path / "r",
        )
