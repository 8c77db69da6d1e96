"""Tiny smoke runs of `vtr train`: both stages, resume, determinism, DDP with 2 CPU processes, `all`."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from vtr import cli
from vtr.training.dataset import save_dataset, synthetic_dataset

REPO = Path(__file__).resolve().parents[2]
# The tiny preset's 3 steps learn nothing: past the stage check (tested in test_stage_check.py)
TINY = ["--preset", "tiny", "--allow-no-gain"]


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("data") / "syn.npz"
    save_dataset(path, synthetic_dataset(frames=80, size=32, episodes=4, seed=0))
    return path


@pytest.fixture(scope="module")
def viewnet(data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "viewnet"
    assert cli.main(["train", "viewnet", *TINY, "--data", str(data), "--out", str(out)]) == 0
    return out


def _lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def _velocitynet(data: Path, viewnet: Path, out: Path, *more: str) -> list[str]:
    """`vtr train velocitynet --preset tiny` argv, then ``more``."""
    tiny = ["train", "velocitynet", *TINY]
    return [*tiny, "--data", str(data), "--viewnet", str(viewnet), "--out", str(out), *more]


def test_viewnet_stage_writes_model_metrics_and_report(viewnet: Path) -> None:
    ckpt = torch.load(viewnet / "model.pt", weights_only=True)
    assert ckpt["kind"] == "viewnet" and ckpt["model_config"]["image_size"] == 32
    rows = _lines(viewnet / "metrics.jsonl")
    assert [r["step"] for r in rows if r["split"] == "train"] == [1, 2, 3]
    assert any(r["split"] == "val" for r in rows)
    report = json.loads((viewnet / "report.json").read_text())
    assert report["model"] == "viewnet" and report["copy_baseline_l1"] > 0


def test_velocitynet_stage_and_report(data: Path, viewnet: Path, tmp_path: Path) -> None:
    out = tmp_path / "vel"
    args = _velocitynet(data, viewnet, out)
    assert cli.main(args) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["model"] == "velocitynet"
    assert report["mean_baseline_mse"] > 0 and report["mse_first_command"] > 0
    val = [r for r in _lines(out / "metrics.jsonl") if r["split"] == "val"]
    assert {"J1", "J2", "img1", "vel1"} <= set(val[-1])


def test_velocitynet_with_augmentation_and_standardised_inputs_exports_its_preprocessing(
    data: Path, viewnet: Path, tmp_path: Path
) -> None:
    from vtr.runtime.policy import OnnxPolicy
    from vtr.runtime.preprocess import STANDARDISED

    out = tmp_path / "vel_aug"
    args = _velocitynet(data, viewnet, out, "--augment", "--preprocessing", STANDARDISED)
    assert cli.main(args) == 0
    ckpt = torch.load(out / "model.pt", weights_only=True)
    assert ckpt["model_config"]["preprocessing"] == STANDARDISED and ckpt["augment"] is True
    onnx = tmp_path / "vel_aug.onnx"
    assert (
        cli.main(["export", "--checkpoint", str(out), "--out", str(onnx), "--data", str(data), "--int8"]) == 0
    )
    assert OnnxPolicy(onnx.with_name("vel_aug-int8.onnx")).meta.preprocessing == STANDARDISED
    assert OnnxPolicy(onnx).meta.preprocessing == STANDARDISED


def test_resume_continues_where_it_stopped(
    data: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "vn"
    base = [
        "train",
        "viewnet",
        *TINY,
        "--data",
        str(data),
        "--out",
        str(out),
        "--val-every",
        "1",
    ]
    assert cli.main([*base, "--steps", "2"]) == 0
    assert cli.main([*base, "--steps", "4"]) == 2  # refuses to overwrite without --resume
    assert "--resume" in capsys.readouterr().err
    assert cli.main([*base, "--steps", "4", "--resume"]) == 0
    steps = [r["step"] for r in _lines(out / "metrics.jsonl") if r["split"] == "train"]
    assert steps == [1, 2, 3, 4]
    assert torch.load(out / "checkpoint.pt", weights_only=True)["step"] == 4


def test_same_seed_same_weights(data: Path, tmp_path: Path) -> None:
    states = []
    for name in ("a", "b"):  # the initial weights too come from --seed, not from the generator's history
        out = tmp_path / name
        cli.main(["train", "viewnet", *TINY, "--data", str(data), "--out", str(out), "--steps", "2"])
        states.append(torch.load(out / "model.pt", weights_only=True)["state_dict"])
    assert all(torch.equal(states[0][k], states[1][k]) for k in states[0])


def test_the_stop_term_is_recorded_and_changes_the_training(
    data: Path, viewnet: Path, tmp_path: Path
) -> None:
    states = []
    for name, w in (("plain", "0"), ("stop", "2.0")):
        out = tmp_path / name
        args = _velocitynet(data, viewnet, out, "--steps", "2", "--w-stop", w, "--threads", "1")
        assert cli.main(args) == 0
        ckpt = torch.load(out / "model.pt", weights_only=False)
        assert ckpt["loss_config"]["w_stop"] == float(w)
        states.append(ckpt["state_dict"])
    # same seed and batches: only the stop term's gradient can make the weights differ
    assert any(not torch.equal(states[0][k], states[1][k]) for k in states[0])


def test_bad_dataset_is_a_message_not_a_traceback(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    assert (
        cli.main(["train", "viewnet", "--preset", "tiny", "--data", str(bad), "--out", str(tmp_path / "o")])
        == 2
    )
    assert "corrupt" in capsys.readouterr().err


def test_torchrun_two_cpu_processes(data: Path, tmp_path: Path) -> None:
    out = tmp_path / "ddp"
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(REPO))
    cmd = [
        sys.executable,
        "-m",
        "torch.distributed.run",
        "--standalone",
        "--nproc_per_node=2",
        "-m",
        "vtr.training.app",
        "viewnet",
        *TINY,
        "--data",
        str(data),
        "--out",
        str(out),
        "--steps",
        "2",
        "--device",
        "cpu",
        "--threads",
        "1",
    ]
    proc = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert (out / "model.pt").exists()
    steps = [r["step"] for r in _lines(out / "metrics.jsonl") if r["split"] == "train"]
    assert steps == [1, 2]  # rank 0 alone writes the log


def test_train_all_collects_trains_and_exports(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import vtr.training.dataset as dataset_mod
    import vtr.training.train as train_mod

    loads: list[str] = []
    real_load = dataset_mod.load_dataset

    def counting_load(path, *args, **kwargs):
        loads.append(str(path))
        return real_load(path, *args, **kwargs)

    monkeypatch.setattr(dataset_mod, "load_dataset", counting_load)
    monkeypatch.setattr(train_mod, "load_dataset", counting_load)
    out, models, data = tmp_path / "run", tmp_path / "models", tmp_path / "data" / "house.npz"
    args = [
        "train",
        "all",
        "--recipe",
        "paper-house",  # the one-house recipe: collect an .npz, one VelocityNet stage
        *TINY,
        "--data",
        str(data),
        "--out",
        str(out),
        "--models-dir",
        str(models),
    ]
    assert cli.main(args) == 0
    assert data.exists()  # there was no dataset: `all` recorded one first
    assert not models.exists()  # never installed without --install-models
    assert len(loads) == 1  # one load serves both stages and the export
    for name in ("velocitynet.onnx", "velocitynet-int8.onnx", "viewnet.pt", "velocitynet.pt"):
        assert (out / "export" / name).exists(), name
    args.append("--install-models")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["export"]["fp32"]["max_abs_err_random"] <= 1e-4
    assert summary["viewnet"]["model"] == "viewnet" and summary["velocitynet"]["model"] == "velocitynet"
    assert {"collect_s", "viewnet_s", "velocitynet_s", "export_s", "total_s"} <= set(summary["timings"])
    # A second run finds every stage done, only re-exports, and installs when asked.
    assert cli.main(args) == 0
    for name in ("velocitynet.onnx", "velocitynet-int8.onnx", "viewnet.pt", "velocitynet.pt"):
        assert (models / name).exists(), name
    assert json.loads((out / "summary.json").read_text())["installed"]
    # The ONNX models carry their recipe and a data summary; the shipped policy can be fine-tuned.
    import onnxruntime as ort

    from vtr.training.checkpoint import load_model

    for name in ("velocitynet.onnx", "velocitynet-int8.onnx"):
        props = ort.InferenceSession(str(models / name)).get_modelmeta().custom_metadata_map
        recipe, data_summary = json.loads(props["vtr.recipe"]), json.loads(props["vtr.data"])
        assert recipe["velocitynet"]["train"]["steps"] == 3 and recipe["viewnet"]["train"]["steps"] == 3
        assert data_summary["frames"] == 60
    assert load_model(models / "velocitynet.pt")[0] == "velocitynet"


@pytest.mark.slow
def test_default_preset_beats_both_baselines(tmp_path: Path) -> None:
    """Real (short) training on a real collected dataset: minutes on a 2-core CPU."""
    pytest.importorskip("pymunk")
    data, out = tmp_path / "house.npz", tmp_path / "run"
    assert cli.main(["collect", "--out", str(data), "--frames", "1500", "--no-progress"]) == 0
    base = ["--preset", "default", "--data", str(data)]
    assert cli.main(["train", "viewnet", *base, "--out", str(out / "vn"), "--steps", "1500"]) == 0
    vel = [
        "train",
        "velocitynet",
        *base,
        "--viewnet",
        str(out / "vn"),
        "--out",
        str(out / "vel"),
        "--steps",
        "800",
    ]
    assert cli.main(vel) == 0
    vn = json.loads((out / "vn" / "report.json").read_text())
    vr = json.loads((out / "vel" / "report.json").read_text())
    assert vn["viewnet_l1"] < 0.9 * vn["copy_baseline_l1"]
    # 1500 frames leave ~85 held-out windows: the VelocityNet ratio varies run to run (0.62, 0.80
    # measured), so this only asks that it beats the baseline; full-data figures are in training/README.md.
    assert vr["mse_first_command"] < vr["mean_baseline_mse"]


def test_interrupt_saves_a_checkpoint_that_resume_continues(
    data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import vtr.training.train as train_mod
    from vtr.training.config import get_preset, override

    preset = get_preset("tiny")
    cfg = override(preset.train_viewnet, steps=5, val_every=100)
    real_loss, calls = train_mod.viewnet_loss, []

    def flaky(*args: object) -> torch.Tensor:
        calls.append(1)
        if len(calls) == 4:
            raise KeyboardInterrupt
        return real_loss(*args)

    monkeypatch.setattr(train_mod, "viewnet_loss", flaky)
    out = tmp_path / "vn"
    with pytest.raises(KeyboardInterrupt):
        train_mod.train_viewnet(data, out, preset.viewnet, cfg)
    assert torch.load(out / "checkpoint.pt", weights_only=True)["step"] == 3
    monkeypatch.setattr(train_mod, "viewnet_loss", real_loss)
    train_mod.train_viewnet(data, out, preset.viewnet, cfg, resume=True)
    assert torch.load(out / "checkpoint.pt", weights_only=True)["step"] == 5
    assert (out / "model.pt").exists()
