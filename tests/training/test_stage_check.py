"""The stage check: a stage whose held-out result does not beat its baseline stops `vtr train` (exit 1)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from vtr import cli
from vtr.training.config import MAX_RATIO
from vtr.training.dataset import save_dataset, synthetic_dataset
from vtr.training.report import NoGainError, check_gain


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("data") / "syn.npz"
    save_dataset(path, synthetic_dataset(frames=80, size=32, episodes=4, seed=0))
    return path


def _viewnet_report(l1: float, reversed_l1: float, copy: float = 0.04) -> dict:
    return {
        "model": "viewnet",
        "viewnet_l1": l1,
        "viewnet_l1_reversed": reversed_l1,
        "copy_baseline_l1": copy,
    }


def test_a_viewnet_that_did_not_learn_stops_the_stage(
    data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "vn"
    argv = ["train", "viewnet", "--preset", "tiny", "--data", str(data), "--out", str(out), "--steps", "1"]
    assert cli.main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]  # the line after the progress bar
    report = json.loads((out / "report.json").read_text())
    assert report["ratio_to_baseline"] > MAX_RATIO  # one step at lr 1e-4 from the copy-the-input start
    assert err.startswith("vtr train viewnet: ViewNet did not learn: held-out L1")
    for words in ("copy-the-input baseline", "--allow-no-gain"):
        assert words in err
    assert f"{report['copy_baseline_l1']:.5f}" in err and f"{report['ratio_to_baseline']:.3f}x" in err
    assert (out / "model.pt").exists()  # kept, so that --allow-no-gain can go on with it


def test_train_all_stops_after_the_viewnet_stage(
    data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "run"
    argv = [
        "train",
        "all",
        "--recipe",
        "paper-house",
        "--preset",
        "tiny",
        "--data",
        str(data),
        "--out",
        str(out),
    ]
    assert cli.main([*argv, "--viewnet-steps", "1", "--no-int8"]) == 1
    err = capsys.readouterr().err
    assert "vtr train all: ViewNet did not learn" in err
    assert (out / "viewnet" / "model.pt").exists() and not (out / "velocitynet").exists()
    # run again: the finished stage is checked again, not skipped past
    assert cli.main([*argv, "--viewnet-steps", "1", "--no-int8"]) == 1
    assert not (out / "velocitynet").exists()


@pytest.mark.parametrize(
    ("report", "stops"),
    [
        (_viewnet_report(0.020, 0.021), False),
        (_viewnet_report(0.0399, 0.0398), True),  # 0.998x: the copy-the-input fixed point
        (_viewnet_report(0.020, 0.039), True),  # one direction not learned
        ({"model": "velocitynet", "mse_first_command": 0.03, "mean_baseline_mse": 0.25}, False),
        ({"model": "velocitynet", "mse_first_command": 0.245, "mean_baseline_mse": 0.25}, True),
    ],
)
def test_check_gain_compares_each_stage_with_its_baseline(report: dict, stops: bool) -> None:
    if not stops:
        check_gain(report, "runs/x")
        return
    with pytest.raises(NoGainError, match="did not learn") as err:
        check_gain(report, "runs/x")
    baseline = "copy-the-input" if report["model"] == "viewnet" else "mean-command"
    assert baseline in str(err.value) and "runs/x" in str(err.value)


def test_allow_no_gain_is_in_the_help(capsys: pytest.CaptureFixture[str]) -> None:
    for stage in ("viewnet", "velocitynet", "all"):
        with pytest.raises(SystemExit):
            cli.main(["train", stage, "--help"])
        assert "--allow-no-gain" in capsys.readouterr().out
