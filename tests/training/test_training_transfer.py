"""Training across houses: house-held-out split, lazy sharded windows, --init weights, offline evaluation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from vtr.training.config import get_preset
from vtr.training.dataset import synthetic_dataset
from vtr.training.distributed import setup_dist
from vtr.training.shards import load_sharded, write_index, write_shard
from vtr.training.train import train_velocitynet, train_viewnet
from vtr.training.transfer import evaluate, init_weights, split_for
from vtr.training.windows import Windows


def _sharded(root: Path, houses: int = 4) -> Path:
    """A sharded dataset of synthetic frames (no simulator), one shard per fake house."""
    shards = []
    for h in range(houses):
        d = synthetic_dataset(frames=48, size=32, episodes=3, seed=h)
        arrays = {"images": d.images, "commands": d.commands, "poses": d.poses, "episodes": d.episodes}
        write_shard(root, f"h{h}", arrays)
        shards.append({"name": f"h{h}", "frames": 48, "episodes": 3, "house": f"random:{h}"})
    write_index(root, 32, 0.1, {"source": "test"}, shards)
    return root


def test_split_holds_out_whole_houses(tmp_path: Path) -> None:
    data = load_sharded(_sharded(tmp_path))
    cfg = get_preset("tiny").train_viewnet
    train_ids, val_ids = split_for(data, cfg)
    assert len(np.intersect1d(train_ids, val_ids)) == 0
    val_houses = set(data.houses[np.isin(data.episodes, val_ids)])
    train_houses = set(data.houses[np.isin(data.episodes, train_ids)])
    assert val_houses and train_houses and not (val_houses & train_houses)
    assert data.meta["held_out_houses"] == [data.house_names[h] for h in sorted(val_houses)]


def test_lazy_windows_gather_the_same_frames_as_in_memory(tmp_path: Path) -> None:
    data = load_sharded(_sharded(tmp_path))
    cfg = get_preset("tiny").train_viewnet
    dist = setup_dist(cfg)
    lazy = Windows(data, 3, cfg, dist)
    starts = lazy.train_starts[:5]
    frames, commands = lazy.gather_raw(starts)
    full = np.asarray(data.images)
    idx = starts[:, None] + np.arange(3)
    np.testing.assert_array_equal(frames.numpy(), full[idx])
    np.testing.assert_array_equal(commands.numpy(), data.commands[idx[:, :-1]])


def test_init_loads_weights_and_refuses_a_mismatch(tmp_path: Path) -> None:
    from vtr.training.models import VelocityNet, ViewNet

    preset = get_preset("tiny")
    data = tmp_path / "d.npz"
    from vtr.training.dataset import save_dataset

    save_dataset(data, synthetic_dataset(frames=64, size=32))
    train_viewnet(data, tmp_path / "v", preset.viewnet, preset.train_viewnet)
    fresh = ViewNet(preset.viewnet)
    note = init_weights(fresh, "viewnet", preset.viewnet, tmp_path / "v")
    trained = torch.load(tmp_path / "v" / "model.pt", weights_only=False)["state_dict"]
    for k, v in fresh.state_dict().items():
        assert torch.equal(v, trained[k]), k
    assert note["init"].endswith("model.pt")
    with pytest.raises(ValueError, match="not a velocitynet"):
        init_weights(VelocityNet(preset.velocitynet), "velocitynet", preset.velocitynet, tmp_path / "v")
    with pytest.raises(ValueError, match="differs from this preset's viewnet in"):
        init_weights(
            ViewNet(get_preset("default").viewnet), "viewnet", get_preset("default").viewnet, tmp_path / "v"
        )
    with pytest.raises(FileNotFoundError, match="ONNX only"):
        init_weights(VelocityNet(preset.velocitynet), "velocitynet", preset.velocitynet, tmp_path / "none.pt")


def test_fine_tune_starts_from_init_and_evaluate_reports_baselines(tmp_path: Path) -> None:
    preset = get_preset("tiny")
    data = _sharded(tmp_path / "ds")
    train_viewnet(data, tmp_path / "v", preset.viewnet, preset.train_viewnet)
    train_velocitynet(
        data, tmp_path / "v", tmp_path / "p", preset.velocitynet, preset.loss, preset.train_velocitynet
    )
    train_velocitynet(
        data,
        tmp_path / "v",
        tmp_path / "p2",
        preset.velocitynet,
        preset.loss,
        preset.train_velocitynet,
        init=tmp_path / "p",
    )
    ckpt = torch.load(tmp_path / "p2" / "model.pt", weights_only=False)
    assert ckpt["init"].endswith("model.pt") and ckpt["data_meta"]["held_out_houses"]
    report = evaluate(str(data), str(tmp_path / "v"), str(tmp_path / "p2"), preset="tiny")
    assert report["viewnet"]["held_out_pairs"] > 100  # every episode of every house
    v = report["velocitynet"]
    assert v["mean_baseline_mse"] > 0 and np.isfinite(v["mse_first_command"])
    assert v["mean_command"] == pytest.approx(ckpt["mean_command"])


def test_a_cli_fine_tune_keeps_the_base_preprocessing_and_augmentation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from vtr import cli
    from vtr.runtime.preprocess import PREPROCESSINGS
    from vtr.training.dataset import save_dataset

    data = tmp_path / "d.npz"
    save_dataset(data, synthetic_dataset(frames=64, size=32))
    tiny = [
        "--data",
        str(data),
        "--preset",
        "tiny",
        "--steps",
        "1",
        "--allow-no-gain",
    ]  # 1 step learns nothing
    assert cli.main(["train", "viewnet", *tiny, "--out", str(tmp_path / "v")]) == 0
    stage = ["train", "velocitynet", *tiny, "--viewnet", str(tmp_path / "v")]
    assert (
        cli.main([*stage, "--out", str(tmp_path / "base"), "--augment", "--preprocessing", PREPROCESSINGS[1]])
        == 0
    )
    assert cli.main([*stage, "--out", str(tmp_path / "ft"), "--init", str(tmp_path / "base")]) == 0
    ckpt = torch.load(tmp_path / "ft" / "model.pt", weights_only=False)
    assert ckpt["model_config"]["preprocessing"] == PREPROCESSINGS[1] and ckpt["augment"] is True
    capsys.readouterr()
    argv = [*stage, "--out", str(tmp_path / "bad"), "--init", str(tmp_path / "base")]
    assert cli.main([*argv, "--preprocessing", PREPROCESSINGS[0]]) != 0  # another one asked for: refused
    assert "differs from this preset's velocitynet in preprocessing" in capsys.readouterr().err


def test_named_maps_are_never_held_out() -> None:
    from types import SimpleNamespace

    from vtr.training.transfer import split_by_house

    names = ["house"] + [f"random:{i}" for i in range(9)]
    houses = np.repeat(np.arange(10), 4)
    data = SimpleNamespace(houses=houses, house_names=names, episodes=np.arange(40) // 2)
    for seed in range(20):
        _, val_ids, held_out = split_by_house(data, 0.3, seed)
        assert held_out and "house" not in held_out
        assert all(h.startswith("random:") for h in held_out)
        assert not np.isin(val_ids, data.episodes[houses == 0]).any()


def test_an_old_viewnet_without_a_velocity_gain_keeps_gain_1_loaded_or_fine_tuned(tmp_path: Path) -> None:
    from vtr.training.checkpoint import load_model, save_checkpoint
    from vtr.training.config import LEGACY_VELOCITY_GAIN, override, to_dict
    from vtr.training.models import ViewNet
    from vtr.training.transfer import init_viewnet_config

    cfg = get_preset("tiny").viewnet
    assert cfg.velocity_gain != LEGACY_VELOCITY_GAIN == 1.0
    old = {k: v for k, v in to_dict(cfg).items() if k != "velocity_gain"}  # written before the gain existed
    path = tmp_path / "old.pt"
    save_checkpoint({"kind": "viewnet", "model_config": old, "state_dict": ViewNet(cfg).state_dict()}, path)
    model = load_model(path)[1]
    assert model.cfg.velocity_gain == 1.0
    assert torch.allclose(model.vel_scale, torch.tensor([1 / cfg.v_max, 1 / cfg.w_max]))
    with pytest.raises(ValueError, match="velocity_gain 1.0"):  # this preset's gain would misread its weights
        init_weights(ViewNet(cfg), "viewnet", cfg, path)
    ft = init_viewnet_config(cfg, path)  # what train_viewnet(init=...) builds: the base's gain
    assert ft == override(cfg, velocity_gain=1.0)
    init_weights(ViewNet(ft), "viewnet", ft, path)
    shipped = Path(__file__).resolve().parents[2] / "models" / "viewnet.pt"
    assert load_model(shipped)[1].cfg.velocity_gain == 1.0  # the shipped ViewNet predates the gain
