"""Frames of the same poses in a house whose floor was laid again, and training that pairs the two appearances."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from vtr import cli
from vtr.training.appearances import swap_appearance
from vtr.training.collect_houses import HousesConfig, run_houses
from vtr.training.config import CollectConfig, MPCLossConfig
from vtr.training.dataset import load_dataset
from vtr.training.losses import mpc_loss

SMALL = CollectConfig(
    image_size=32,
    episode_min=20,
    episode_max=40,
    mix="repeat",
    reverse_fraction=0.2,
    progress=False,
    appearances=2,
)
TINY = ["--preset", "tiny", "--allow-no-gain"]


@pytest.fixture(scope="module")
def looks(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("looks") / "ds"
    cfg = HousesConfig(
        out=str(out), seeds=(3,), frames_per_house=80, workers=1, collect=SMALL, named=("house",)
    )
    run_houses(cfg, progress=False)
    return out


def test_the_other_appearance_changes_the_floor_at_the_same_poses(looks: Path) -> None:
    data = load_dataset(looks)
    assert data.alt_images is not None and data.alt_images.shape == data.images.shape
    a, b = np.asarray(data.images).astype(int), np.asarray(data.alt_images).astype(int)
    floor = np.abs(a[:, 20:] - b[:, 20:]).mean()  # the lower rows see the floor
    assert floor > 10, floor
    # walls and furniture keep their finish in most versions: the upper rows change less than the floor
    assert np.abs(a[:, :10] - b[:, :10]).mean() < floor


def test_a_dataset_without_other_appearances_is_refused_for_the_swap(tmp_path: Path) -> None:
    out = tmp_path / "plain"
    plain = CollectConfig(image_size=32, episode_min=20, episode_max=40, mix="repeat", progress=False)
    run_houses(HousesConfig(out=str(out), seeds=(3,), frames_per_house=60, workers=1, collect=plain), False)
    assert load_dataset(out).alt_images is None
    vn = tmp_path / "vn"
    assert cli.main(["train", "viewnet", *TINY, "--data", str(out), "--out", str(vn)]) == 0
    argv = [
        "train",
        "velocitynet",
        *TINY,
        "--data",
        str(out),
        "--viewnet",
        str(vn),
        "--out",
        str(tmp_path / "v"),
    ]
    assert cli.main([*argv, "--appearance-swap", "0.5"]) == 2


def test_swap_takes_one_side_from_the_other_appearance() -> None:
    frames, other = torch.zeros(400, 3, 1, 2, 2), torch.ones(400, 3, 1, 2, 2)
    gen = torch.Generator().manual_seed(0)
    cur, goal = swap_appearance(frames, other, 0.0, gen)
    assert cur.sum() == 0 and goal.sum() == 0
    cur, goal = swap_appearance(frames, other, 1.0, gen)
    c, g = cur.flatten(1).mean(1), goal.flatten(1).mean(1)
    assert torch.all(c + g == 1)  # every window: exactly one side from the other appearance
    assert 150 < int(g.sum()) < 250  # about half of them the subgoal
    cur, goal = swap_appearance(frames, other, 0.5, gen)
    assert 150 < int((cur.flatten(1).mean(1) + goal.flatten(1).mean(1)).sum()) < 250


def test_the_loss_takes_its_subgoals_from_the_goal_frames_only() -> None:
    torch.manual_seed(0)
    frames, goals, commands = torch.rand(4, 3, 3, 8, 8), torch.rand(4, 3, 3, 8, 8), torch.rand(4, 2, 2)
    seen = []

    def policy(current: torch.Tensor, subgoal: torch.Tensor) -> torch.Tensor:
        seen.append((current, subgoal))
        return torch.zeros(current.shape[0], 2, 2)

    def viewnet(image: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        return image

    cfg = MPCLossConfig()
    same, _ = mpc_loss(policy, viewnet, frames, commands, cfg)
    other, _ = mpc_loss(policy, viewnet, frames, commands, cfg, goals)
    assert torch.equal(same, other)  # the image targets and the current images are still ``frames``
    (c0, g0), (c1, g1) = seen
    assert torch.equal(c0, c1) and torch.equal(g0, torch.cat([frames[:, 2], frames[:, 0]]))
    assert torch.equal(g1, torch.cat([goals[:, 2], goals[:, 0]]))


def test_training_with_the_swap_runs_and_records_it(looks: Path, tmp_path: Path) -> None:
    vn = tmp_path / "vn"
    assert cli.main(["train", "viewnet", *TINY, "--data", str(looks), "--out", str(vn)]) == 0
    out = tmp_path / "vel"
    argv = ["train", "velocitynet", *TINY, "--data", str(looks), "--viewnet", str(vn), "--out", str(out)]
    assert cli.main([*argv, "--appearance-swap", "0.5"]) == 0
    ckpt = torch.load(out / "model.pt", weights_only=True)
    assert ckpt["train_config"]["appearance_swap"] == 0.5
    assert json.loads((out / "report.json").read_text())["mse_first_command"] > 0


def test_the_shipped_recipe_collects_two_appearances_and_swaps_in_its_last_stage() -> None:
    from types import SimpleNamespace

    from vtr.pipeline import _houses_config, _train_cfg
    from vtr.training import recipe as recipes
    from vtr.training.config import get_preset

    r = recipes.load("shipped")
    preset = get_preset(r.preset)
    assert _houses_config(r, preset).collect.appearances == 4
    how = SimpleNamespace(device=None, workers=None, amp=None, data_on_device=None, max_minutes=None)
    swaps = [_train_cfg(preset.train_velocitynet, s, how).appearance_swap for s in r.velocitynet]
    assert swaps == [0.0, 0.0, 0.0, 0.5]


def test_the_model_metadata_records_the_appearances_and_the_swap() -> None:
    from vtr.export.provenance import _TRAIN_FIELDS, data_summary

    assert data_summary({"collect_config": {"appearances": 4}})["appearances"] == 4
    assert "appearances" not in data_summary({"collect_config": {"appearances": 0}})
    assert "appearance_swap" in _TRAIN_FIELDS


def test_training_with_the_floor_consistency_term_runs_and_records_it(looks: Path, tmp_path: Path) -> None:
    vn = tmp_path / "vn"
    assert cli.main(["train", "viewnet", *TINY, "--data", str(looks), "--out", str(vn)]) == 0
    out = tmp_path / "vel"
    argv = ["train", "velocitynet", *TINY, "--data", str(looks), "--viewnet", str(vn), "--out", str(out)]
    assert cli.main([*argv, "--w-consistency", "1", "--w-stop", "0.5"]) == 0
    ckpt = torch.load(out / "model.pt", weights_only=True)
    assert ckpt["loss_config"]["w_consistency"] == 1.0


def test_a_sharded_dataset_is_gathered_on_the_host_even_when_asked_to_live_on_the_device(looks: Path) -> None:
    # On a GPU lease the floor stage of the paper preset (4 loader workers) crashed: its commands had gone to the
    # device while its frames stayed in memory maps, and the forked workers indexed both ("Cannot re-initialize
    # CUDA in forked subprocess"). A sharded dataset now keeps its commands on the host with its frames.
    from vtr.training.config import TrainConfig
    from vtr.training.distributed import Dist
    from vtr.training.windows import Windows

    data = load_dataset(looks)
    dist = Dist()
    windows = Windows(data, 3, TrainConfig(batch_size=4, data_on_device="yes"), dist, alt=True)
    assert not windows.on_device and windows.commands.device.type == "cpu"
    batches = list(windows.loader(windows.train_batches(4, 0, 0, dist), 2, workers=2))  # forked workers
    assert len(batches) == 2
    frames, commands = batches[0]
    assert frames.shape[:2] == (4, 6) and commands.shape == (4, 2, 2)  # both appearances, three frames each
