"""export/provenance.py: the recipe and data summary written into a model's metadata."""

from __future__ import annotations

import json

from vtr.export.provenance import DATA_KEY, RECIPE_KEY, camera_of, data_summary, provenance_props


def test_data_summary_names_houses_compactly_and_keeps_the_held_out_ones() -> None:
    meta = {
        "source": "vtr collect --houses",
        "house_seeds": [0, 1, 2, 3, 7, 9, 10],
        "named_houses": ["house"],
        "held_out_houses": ["random:3"],
        "collect_config": {"mix": "repeat", "seed": 0},
        "shards": ["not", "kept"],
    }
    out = data_summary(meta, frames=1234)
    assert out["procedural_houses"] == "random:{0-3,7,9-10}"
    assert out["houses"] == 8 and out["frames"] == 1234 and out["mix"] == "repeat"
    assert out["held_out_houses"] == ["random:3"] and "shards" not in out


def test_props_are_json_and_the_camera_comes_from_the_data_when_recorded() -> None:
    ckpt = {"model_config": {"channels": [4]}, "train_config": {"lr": 0.001, "steps": 9, "device": "cpu"}}
    props = provenance_props(ckpt, None, frames=10)
    recipe = json.loads(props[RECIPE_KEY])
    assert recipe["velocitynet"]["train"] == {"lr": 0.001, "steps": 9}
    assert json.loads(props[DATA_KEY]) == {"frames": 10}
    assert camera_of({"camera": {"fov_deg": 70, "height_m": 0.5}}) == {
        "camera_fov_deg": 70.0,
        "camera_height_m": 0.5,
    }
    assert camera_of({"camera": {"width": 128}}) == {}


def test_a_fine_tune_names_its_start_and_that_starts_settings() -> None:
    start = {"model_config": {"channels": [4]}, "train_config": {"lr": 1e-3, "steps": 4000}}
    tuned = {**start, "train_config": {"lr": 3e-4, "steps": 4000}, "init": "runs/a/velocitynet/model.pt"}
    out = json.loads(provenance_props(tuned, {"train_config": {"steps": 2000}}, start)[RECIPE_KEY])
    assert out["velocitynet"]["train"]["lr"] == 3e-4
    assert out["velocitynet"]["init"] == "a/velocitynet/model.pt"  # no local absolute paths
    assert out["velocitynet"]["init_stage"]["train"] == {"lr": 1e-3, "steps": 4000}
    assert out["viewnet"]["train"] == {"steps": 2000}


def test_a_training_stopped_by_its_budget_says_where() -> None:
    """--max-minutes stops before ``steps``: the metadata gives both (the floors model: 2,475 of 3,000)."""
    ckpt = {"model_config": {}, "train_config": {"lr": 1e-4, "steps": 3000}, "steps_done": 2475}
    recipe = json.loads(provenance_props(ckpt, None)[RECIPE_KEY])
    assert recipe["velocitynet"]["train"] == {"lr": 1e-4, "steps": 3000, "steps_done": 2475}
