"""Collection across cameras: each house records with a camera drawn from the ranges, and the export writes
those ranges into the model's metadata."""

from __future__ import annotations

import pytest

from vtr.export.provenance import camera_of
from vtr.runtime.model_meta import CameraRange, ModelMeta
from vtr.training.collect_houses import house_camera
from vtr.training.config import CollectConfig


def test_each_house_draws_its_camera_from_the_ranges():
    cfg = CollectConfig(image_size=32, fov_range=(60.0, 120.0), height_range=(0.15, 0.6))
    cams = [house_camera(cfg, seed) for seed in range(12)]
    assert all(60 <= c.fov_deg <= 120 and 0.15 <= c.camera_height <= 0.6 and c.width == 32 for c in cams)
    assert len({(c.fov_deg, c.camera_height) for c in cams}) == 12  # a camera per house
    assert house_camera(cfg, 3) == cams[3]  # the same house, the same camera
    plain = house_camera(CollectConfig(image_size=32), 3)
    assert (plain.fov_deg, plain.camera_height) == (90.0, 0.3)


def test_the_export_writes_the_collection_ranges():
    cfg = CollectConfig(fov_range=(60.0, 120.0), height_range=(0.15, 0.6))
    meta = {"collect_config": {"fov_range": list(cfg.fov_range), "height_range": list(cfg.height_range)}}
    assert ModelMeta(**camera_of(meta)).camera_range == CameraRange((60.0, 120.0), (0.15, 0.6))
    only_fov = camera_of({"collect_config": {"fov_range": [70.0, 110.0], "height_range": None}})
    assert ModelMeta(**only_fov).camera_range == CameraRange((70.0, 110.0), (0.3, 0.3))
    assert "camera_fov_min_deg" not in camera_of({"collect_config": {"fov_range": None}})


def test_bad_ranges_are_one_line_errors():
    with pytest.raises(ValueError, match="fov_range must be"):
        CollectConfig(fov_range=(120.0, 60.0))
    with pytest.raises(ValueError, match="height_range must be"):
        CollectConfig(height_range=(0.0, 0.5))
