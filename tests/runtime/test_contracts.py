"""One source per contract: every package's defaults come from runtime.contracts."""

from __future__ import annotations

from vtr.runtime import contracts, protocol
from vtr.runtime.model_meta import ModelMeta
from vtr.runtime.route import Route
from vtr.runtime.teach import TeachConfig


def test_runtime_defaults_come_from_the_contracts():
    assert (protocol.V_MAX, protocol.W_MAX) == (contracts.V_MAX, contracts.W_MAX) == (0.5, 1.0)
    meta = ModelMeta()
    assert (meta.v_max, meta.w_max, meta.dt) == (contracts.V_MAX, contracts.W_MAX, contracts.CONTROL_DT)
    assert (meta.image_height, meta.image_width) == (contracts.CAMERA.height, contracts.CAMERA.width)
    assert TeachConfig().dt == contracts.CONTROL_DT == 0.1
    assert Route.__dataclass_fields__["dt"].default == contracts.CONTROL_DT


def test_simulator_and_training_defaults_come_from_the_contracts():
    from vtr.sim2d.config import CameraConfig, Pose, SimConfig
    from vtr.training.config import CollectConfig, VelocityNetConfig, ViewNetConfig

    cam = CameraConfig()
    spec = contracts.CAMERA
    assert (cam.width, cam.height, cam.fov_deg, cam.camera_height) == (
        spec.width,
        spec.height,
        spec.fov_deg,
        spec.height_m,
    )
    assert (SimConfig().v_max, SimConfig().w_max) == (contracts.V_MAX, contracts.W_MAX)
    assert Pose is contracts.Pose
    for cfg in (CollectConfig(), ViewNetConfig(), VelocityNetConfig()):
        assert (cfg.v_max, cfg.w_max, cfg.image_size) == (contracts.V_MAX, contracts.W_MAX, spec.width)
    assert CollectConfig().dt == contracts.CONTROL_DT
