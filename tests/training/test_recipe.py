"""`vtr train all` runs a recipe file: the shipped one by default, resumable, one line for a bad recipe."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

from vtr import cli
from vtr.training import recipe as recipes
from vtr.training.collect_houses import HousesConfig, run_houses
from vtr.training.config import CollectConfig


def _train_steps(stage_dir: Path) -> list[int]:
    rows = [json.loads(line) for line in (stage_dir / "metrics.jsonl").read_text().splitlines()]
    return [r["step"] for r in rows if r["split"] == "train"]


def test_tiny_recipe_end_to_end_resumes_an_interrupted_stage_and_installs_only_when_asked(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import vtr.training.train as train_mod

    out, data, models = tmp_path / "run", tmp_path / "data", tmp_path / "models"
    argv = ["train", "all", "--recipe", "tiny-test", "--out", str(out), "--data", str(data)]
    argv += ["--models-dir", str(models), "--allow-no-gain"]  # 3 tiny steps learn nothing: go on

    # Ctrl-C in the last stage's first step (the tiny preset logs every step: viewnet 3, velocitynet 3 calls)
    calls = {"n": 0}
    real_any_rank = train_mod.any_rank

    def interrupt_in_stage_b(dist: object, flag: bool) -> bool:
        calls["n"] += 1
        if calls["n"] == 7:
            raise KeyboardInterrupt
        return real_any_rank(dist, flag)

    monkeypatch.setattr(train_mod, "any_rank", interrupt_in_stage_b)
    assert cli.main(argv) != 0
    assert (out / "velocitynet_b" / "checkpoint.pt").exists() and not (
        out / "velocitynet_b" / "model.pt"
    ).exists()
    monkeypatch.setattr(train_mod, "any_rank", real_any_rank)
    capsys.readouterr()

    assert cli.main(argv) == 0  # the same command again: finished stages skipped, the interrupted one resumed
    err = capsys.readouterr().err
    for line in ("[1/5] collect: done, skipped", "[2/5] viewnet: done, skipped", "[3/5] velocitynet: done"):
        assert line in err
    assert "[4/5] velocitynet_b: resume" in err and "[5/5] export" in err
    assert _train_steps(out / "velocitynet_b") == [1, 2]  # step 1 before Ctrl-C, step 2 after
    assert _train_steps(out / "viewnet") == [1, 2, 3]  # trained once
    index = json.loads((data / "index.json").read_text())
    assert sorted({s["house"] for s in index["shards"]}) == ["house", "random:0", "random:1"]
    for name in ("velocitynet.onnx", "velocitynet-int8.onnx", "viewnet.pt", "velocitynet.pt"):
        assert (out / "export" / name).exists(), name
    assert not models.exists()  # never installed without --install-models
    summary = json.loads((out / "summary.json").read_text())
    assert summary["recipe"] == "tiny-test" and set(summary["stages"]) == {
        "viewnet",
        "velocitynet",
        "velocitynet_b",
    }
    assert {"collect_s", "viewnet_s", "velocitynet_s", "velocitynet_b_s", "export_s"} <= set(
        summary["timings"]
    )
    ckpt = summary["export"]["fp32"]
    assert ckpt["max_abs_err_random"] <= 1e-4 and "int8" in summary["export"]
    # the second stage started from the first and kept its input normalisation
    from vtr.training.checkpoint import read_checkpoint

    b = read_checkpoint(out / "velocitynet_b" / "model.pt")
    assert str(b["init"]).endswith("velocitynet/model.pt") and b["train_config"]["lr"] == 3e-4
    assert (
        b["model_config"]["preprocessing"].endswith("channel_standardised") and b["train_config"]["augment"]
    )

    assert cli.main([*argv, "--install-models"]) == 0  # everything done: export again, install
    assert sorted(os.listdir(models)) == [
        "velocitynet-int8.onnx",
        "velocitynet.onnx",
        "velocitynet.pt",
        "viewnet.pt",
    ]

    capsys.readouterr()  # another recipe in the same run folder is one line, exit 2
    assert cli.main([*argv, "--velocitynet-steps", "9"]) == 2
    err = capsys.readouterr().err.strip()
    assert (
        len(err.splitlines()) == 1 and "another recipe (velocitynet[0].options.steps: 3 there, 9 now)" in err
    )


def test_the_shipped_recipe_is_the_base_one_and_its_floors_stage(capsys: pytest.CaptureFixture[str]) -> None:
    base = recipes.load("base")
    assert base.preset == "default" and base.data == "data/houses40" and base.int8
    assert base.collect["houses"] == 40 and base.collect["frames_per_house"] == 2000
    assert base.collect["include_house"] == ["house"] and base.collect["include_house_frames"] == 10000
    steps = [(s.name, s.init, s.options["steps"], s.options.get("lr")) for s in base.velocitynet]
    base_stages = [
        ("velocitynet", None, 4000, None),
        ("velocitynet_b", "velocitynet", 4000, 3e-4),
        ("velocitynet_c", "velocitynet_b", 1500, 3e-4),
    ]
    assert steps == base_stages
    shipped = recipes.load("shipped")  # the default: the base recipe on data in 4 appearances, + floors
    assert {k: v for k, v in shipped.collect.items() if k != "appearances"} == base.collect
    assert shipped.collect["appearances"] == 4
    steps = [(s.name, s.init, s.options["steps"], s.options.get("lr")) for s in shipped.velocitynet]
    assert steps == [*base_stages, ("velocitynet_floors", "velocitynet_c", 2475, 1e-4)]
    floors = shipped.velocitynet[-1].options
    assert floors["batch_size"] == 64 and floors["appearance_swap"] == 0.5 and floors["w_consistency"] == 0.3
    assert (
        cli.main(["train", "all", "--dry-run", "--out", "/nonexistent/run", "--data", "/nonexistent/d"]) == 0
    )
    lines = capsys.readouterr().out.splitlines()
    assert (
        lines[0]
        == "vtr train all [1/7] collect: to run: 90,000 frames in 41 houses into /nonexistent/d (0 recorded)"
    )
    assert "[5/7] velocitynet_c: to run: train 1500 steps from velocitynet_b" in lines[4]
    assert "[6/7] velocitynet_floors: to run: train 2475 steps from velocitynet_c" in lines[5]
    assert not Path("/nonexistent").exists()


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ('preset = "huge"', "preset must be one of"),
        ("colect = {}", "unknown key 'colect'"),
        ("[viewnet]\nsteps = 'many'", "steps = 'many' is not int"),
        ("[viewnet]\nlearning_rate = 1e-3", "unknown key 'learning_rate'"),
        ('[[velocitynet]]\nname = "a"\ninit = "b"', "starts from 'b', not an earlier stage"),
        ("[collect\nhouses = 3", "recipe"),  # not TOML
    ],
)
def test_a_bad_recipe_is_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, says: str
) -> None:
    path = tmp_path / "r.toml"
    path.write_text(text + "\n")
    assert cli.main(["train", "all", "--recipe", str(path), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("vtr train all: ") and says in err
    assert not (tmp_path / "run").exists()


def test_unknown_recipe_names_the_known_ones(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["train", "all", "--recipe", "nope"]) == 2
    assert "known: base, cpu, paper-house, shipped, tiny-test" in capsys.readouterr().err


def test_an_interrupted_collection_keeps_the_houses_it_finished(tmp_path: Path) -> None:
    collect = CollectConfig(image_size=32, episode_min=10, episode_max=20, far_clearance=0.5, mix="repeat")
    cfg = HousesConfig(out=str(tmp_path), seeds=(0, 1), frames_per_house=30, workers=1, collect=collect)
    run_houses(cfg, progress=False)
    index = json.loads((tmp_path / "index.json").read_text())
    kept = tmp_path / f"{index['shards'][0]['name']}.images.npy"
    before = kept.stat().st_mtime_ns
    index["shards"] = index["shards"][:1]  # as if killed while recording the second house
    (tmp_path / "index.json").write_text(json.dumps(index))
    summary = run_houses(cfg, progress=False, resume=True)
    assert summary["kept_frames"] == 30 and kept.stat().st_mtime_ns == before
    assert len(json.loads((tmp_path / "index.json").read_text())["shards"]) == 2
    other = HousesConfig(out=str(tmp_path), seeds=(0, 1), frames_per_house=30, workers=1, collect=collect)
    other = HousesConfig(**{**other.__dict__, "collect": CollectConfig(image_size=32, seed=5, mix="repeat")})
    with pytest.raises(ValueError, match="recorded with other settings"):
        run_houses(other, progress=False, resume=True)


def test_a_recipe_stage_sets_the_floor_consistency_weight(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """`w_consistency` in a VelocityNet stage reaches the stage's loss (a key the recipe takes but drops would
    train another model than the file says)."""
    import argparse

    from vtr import pipeline
    from vtr.training import train
    from vtr.training.config import get_preset
    from vtr.training.recipe import Stage

    seen: dict[str, object] = {}

    def fake_train(data, viewnet, sdir, model_cfg, loss, cfg, resume, loaded, init):  # noqa: ANN001, ANN202
        seen["loss"] = loss

    monkeypatch.setattr(train, "train_velocitynet", fake_train)
    recipe = recipes.load("tiny-test")
    stage = Stage("velocitynet", {"w_consistency": 0.25, "steps": 1})
    args = argparse.Namespace(device="cpu", workers=0, amp=None, data_on_device=None, max_minutes=None)
    pipeline._velocitynet(tmp_path, recipe, stage, get_preset(recipe.preset), args, None)
    assert seen["loss"].w_consistency == 0.25


def test_the_cpu_recipe_is_the_shipped_one_with_its_floors_stage_at_batch_32() -> None:
    shipped, cpu = recipes.load("shipped"), recipes.load("cpu")
    assert (cpu.preset, cpu.data, cpu.collect, cpu.int8) == (
        shipped.preset,
        shipped.data,
        shipped.collect,
        True,
    )

    def trained(r: recipes.Recipe) -> list[tuple[str, str | None, dict[str, Any]]]:
        drop = ("threads", "batch_size")  # how a stage runs, and the one change
        return [
            (s.name, s.init, {k: v for k, v in s.options.items() if k not in drop})
            for s in [r.viewnet, *r.velocitynet]
        ]

    assert trained(cpu) == trained(shipped)
    assert [s.options.get("batch_size") for s in cpu.velocitynet] == [None, None, None, 32]
    assert shipped.velocitynet[-1].options["batch_size"] == 64
    assert not any("threads" in s.options for s in [cpu.viewnet, *cpu.velocitynet])  # the preset's 2


@pytest.mark.parametrize(
    ("recipe", "cuda", "hint"), [("shipped", False, True), ("cpu", False, False), ("shipped", True, False)]
)
def test_the_shipped_recipe_on_a_cpu_points_to_the_cpu_one(
    recipe: str, cuda: bool, hint: bool, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: cuda)
    argv = [
        "train",
        "all",
        "--recipe",
        recipe,
        "--dry-run",
        "--out",
        "/nonexistent/run",
        "--data",
        "/nonexistent/d",
    ]
    assert cli.main(argv) == 0
    assert ("`--recipe cpu` is this recipe sized for one" in capsys.readouterr().err) == hint
    assert not Path("/nonexistent").exists()
