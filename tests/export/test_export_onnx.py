"""export_onnx: checker, metadata, parity with torch, cv2.dnn agrees with onnxruntime, int8, the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from vtr import cli
from vtr.export.cli import ExportConfig, int8_path, model_dt
from vtr.export.cli import run as export_run
from vtr.export.onnx_export import ParityError, check_parity, export_onnx, velocitynet_meta
from vtr.export.quantize import calibration_pairs, compare, quantize_int8
from vtr.runtime.model_meta import INPUT_CURRENT, INPUT_SUBGOAL, OUTPUT_VELOCITIES, ModelMeta
from vtr.training.checkpoint import save_checkpoint
from vtr.training.config import VelocityNetConfig, ViewNetConfig, to_dict
from vtr.training.dataset import save_dataset, synthetic_dataset
from vtr.training.models import VelocityNet, ViewNet

SIZE = 32


def _velocitynet(seed: int = 0) -> VelocityNet:
    """A VelocityNet with non-trivial BatchNorm statistics, so folding them is exercised."""
    torch.manual_seed(seed)
    net = VelocityNet(VelocityNetConfig(image_size=SIZE, channels=(8, 8, 16, 16, 16, 16, 16)))
    for m in net.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.2, 0.2)
            m.running_var.uniform_(0.5, 2.0)
            m.weight.data.uniform_(0.5, 1.5)
    return net.eval()


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, VelocityNet, dict]:
    net = _velocitynet()
    path = tmp_path_factory.mktemp("onnx") / "velocitynet.onnx"
    real = [np.random.default_rng(5).random((4, 3, SIZE, SIZE), dtype=np.float32) for _ in range(2)]
    result = export_onnx(net, path, velocitynet_meta(net.cfg), opset=17, real_inputs=real)
    return path, net, result


def test_export_passes_the_full_checker_and_keeps_the_opset(exported: tuple[Path, VelocityNet, dict]) -> None:
    path, _, result = exported
    proto = onnx.load(path)
    onnx.checker.check_model(proto, full_check=True)
    assert {o.domain: o.version for o in proto.opset_import}.get("", None) == 17
    assert [i.name for i in proto.graph.input] == [INPUT_CURRENT, INPUT_SUBGOAL]
    assert [o.name for o in proto.graph.output] == [OUTPUT_VELOCITIES]
    assert "BatchNormalization" not in {n.op_type for n in proto.graph.node}  # folded into the convs
    assert result["max_abs_err_random"] <= 1e-5 and result["max_abs_err_real"] <= 1e-5


def test_metadata_round_trips_through_model_meta(exported: tuple[Path, VelocityNet, dict]) -> None:
    path, net, _ = exported
    props = {p.key: p.value for p in onnx.load(path).metadata_props}
    meta = ModelMeta.from_props(props)
    assert meta == velocitynet_meta(net.cfg)
    assert (meta.image_height, meta.horizon, meta.v_max, meta.w_max) == (SIZE, 2, 0.5, 1.0)
    sess_meta = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]).get_modelmeta()
    assert sess_meta.custom_metadata_map == props


def test_onnxruntime_matches_torch_on_a_dynamic_batch(exported: tuple[Path, VelocityNet, dict]) -> None:
    path, net, _ = exported
    rng = np.random.default_rng(9)
    cur, sub = (rng.random((3, 3, SIZE, SIZE), dtype=np.float32) for _ in range(2))
    got = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"]).run(
        None, {INPUT_CURRENT: cur, INPUT_SUBGOAL: sub}
    )[0]
    want = net(torch.from_numpy(cur), torch.from_numpy(sub)).detach().numpy()
    assert got.shape == (3, 2, 2)
    np.testing.assert_allclose(got, want, atol=1e-5)


def test_cv2_dnn_gives_the_same_outputs_as_onnxruntime(exported: tuple[Path, VelocityNet, dict]) -> None:
    cv2 = pytest.importorskip("cv2")
    path, _, _ = exported
    rng = np.random.default_rng(3)
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    net = cv2.dnn.readNetFromONNX(str(path))
    for _ in range(3):
        cur, sub = (rng.random((1, 3, SIZE, SIZE), dtype=np.float32) for _ in range(2))
        want = sess.run(None, {INPUT_CURRENT: cur, INPUT_SUBGOAL: sub})[0]
        net.setInput(cur, INPUT_CURRENT)
        net.setInput(sub, INPUT_SUBGOAL)
        got = np.asarray(net.forward()).reshape(want.shape)
        np.testing.assert_allclose(got, want, atol=1e-5)


def test_parity_check_raises_past_the_tolerance(exported: tuple[Path, VelocityNet, dict]) -> None:
    path, _, _ = exported
    other = _velocitynet(seed=1)
    x = [np.random.default_rng(0).random((2, 3, SIZE, SIZE), dtype=np.float32) for _ in range(2)]
    with pytest.raises(ParityError, match="tolerance"):
        check_parity(other, str(path), [INPUT_CURRENT, INPUT_SUBGOAL], x, atol=1e-5)


def test_runtime_policy_loads_the_export(exported: tuple[Path, VelocityNet, dict]) -> None:
    policy_mod = pytest.importorskip("vtr.runtime.policy")
    path, net, _ = exported
    policy = policy_mod.OnnxPolicy(path)
    rng = np.random.default_rng(1)
    cur, sub = (rng.integers(0, 256, (SIZE, SIZE, 3), dtype=np.uint8) for _ in range(2))
    from vtr.runtime.preprocess import to_nchw

    want = net(torch.from_numpy(to_nchw(cur)), torch.from_numpy(to_nchw(sub))).detach().numpy()[0]
    np.testing.assert_allclose(policy.predict(cur, sub), want, atol=1e-5)


def test_viewnet_exports_with_gridsample(tmp_path: Path) -> None:
    torch.manual_seed(0)
    net = ViewNet(
        ViewNetConfig(image_size=SIZE, encoder_channels=(4,) * 8, decoder_channels=(4, 4), flow_resolution=16)
    )
    torch.nn.init.normal_(net.flow.weight, std=0.05)
    meta = ModelMeta(image_height=SIZE, image_width=SIZE)
    sample = (torch.rand(1, 3, SIZE, SIZE), torch.zeros(1, 2))
    real = [
        np.random.default_rng(0).random((2, 3, SIZE, SIZE), dtype=np.float32),
        np.full((2, 2), 0.3, np.float32),
    ]
    path = tmp_path / "viewnet.onnx"
    result = export_onnx(
        net,
        path,
        meta,
        opset=17,
        sample_inputs=sample,
        real_inputs=real,
        input_names=("image", "velocity"),
        output_names=("predicted",),
        atol=1e-4,
    )
    assert "GridSample" in {n.op_type for n in onnx.load(path).graph.node}
    assert result["max_abs_err_real"] <= 1e-4


def test_int8_model_loads_and_stays_close(exported: tuple[Path, VelocityNet, dict], tmp_path: Path) -> None:
    path, _, _ = exported
    data = synthetic_dataset(frames=60, size=SIZE, episodes=3, seed=2)
    cur, sub = calibration_pairs(data.images, data.episodes, count=16, seed=0)
    q_path = tmp_path / "q.onnx"
    quantize_int8(path, q_path, cur, sub)
    proto = onnx.load(q_path)
    ops = {n.op_type for n in proto.graph.node}
    assert {"QuantizeLinear", "DequantizeLinear"} <= ops
    assert ModelMeta.from_props({p.key: p.value for p in proto.metadata_props}).horizon == 2
    held = calibration_pairs(data.images, data.episodes, count=16, seed=1)
    stats = compare(path, q_path, *held, repeats=3)
    assert stats["max_abs_err_v"] < 0.05 and stats["max_abs_err_w"] < 0.1
    assert stats["speedup"] > 0


def test_export_cli_writes_fp32_int8_and_viewnet(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    net = _velocitynet()
    ckpt = tmp_path / "velocitynet.pt"
    save_checkpoint(
        {"kind": "velocitynet", "model_config": to_dict(net.cfg), "state_dict": net.state_dict()}, ckpt
    )
    vcfg = ViewNetConfig(
        image_size=SIZE, encoder_channels=(4,) * 8, decoder_channels=(4, 4), flow_resolution=16
    )
    vckpt = tmp_path / "viewnet.pt"
    save_checkpoint(
        {"kind": "viewnet", "model_config": to_dict(vcfg), "state_dict": ViewNet(vcfg).state_dict()}, vckpt
    )
    data = tmp_path / "d.npz"
    save_dataset(data, synthetic_dataset(frames=60, size=SIZE, episodes=3))
    out = tmp_path / "m" / "velocitynet.onnx"
    args = [
        "export",
        "--checkpoint",
        str(ckpt),
        "--out",
        str(out),
        "--int8",
        "--data",
        str(data),
        "--viewnet",
        str(vckpt),
    ]
    assert cli.main(args) == 0
    printed = capsys.readouterr()
    report = json.loads(printed.out)
    assert "records no dataset dt" in printed.err  # this checkpoint has no data_meta: said, not silent
    assert out.exists() and int8_path(out).exists() and (out.parent / "viewnet.onnx").exists()
    # the 60 calibration frames are not what this checkpoint (which names no data) was trained on: not claimed
    props = {p.key: p.value for p in onnx.load(out).metadata_props}
    assert "frames" not in json.loads(props["vtr.data"])
    # ViewNet's ONNX says what it is and does not pass for a policy
    vprops = {p.key: p.value for p in onnx.load(out.parent / "viewnet.onnx").metadata_props}
    assert vprops["vtr.kind"] == "viewnet" and "vtr.horizon" not in vprops
    from vtr.runtime.policy import ModelMismatchError, OnnxPolicy

    with pytest.raises(ModelMismatchError, match="horizon"):
        OnnxPolicy(out.parent / "viewnet.onnx")
    assert report["fp32"]["max_abs_err_real"] <= 1e-4
    assert "speedup" in report["int8"]
    # an export never replaces a file unasked: every output that exists is refused without --force
    before = {p: p.stat().st_mtime_ns for p in (out, int8_path(out), out.parent / "viewnet.onnx")}
    assert cli.main(args) == 2 and "exists; pass --force" in capsys.readouterr().err
    assert {p: p.stat().st_mtime_ns for p in before} == before
    only_viewnet = [
        "export",
        "--checkpoint",
        str(ckpt),
        "--out",
        str(out.parent / "new.onnx"),
        "--viewnet",
        str(vckpt),
    ]
    assert cli.main(only_viewnet) == 2 and "viewnet.onnx exists" in capsys.readouterr().err
    assert not (out.parent / "new.onnx").exists()
    # int8 without calibration frames, or a ViewNet given as the policy, are clear errors
    assert cli.main(["export", "--checkpoint", str(ckpt), "--out", str(out), "--int8", "--force"]) == 2
    with pytest.raises(ValueError, match="holds a viewnet"):
        export_run(ExportConfig(checkpoint=str(vckpt), out=str(out)))


def test_the_model_dt_is_the_datasets_or_given_or_the_control_step_said_aloud(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert model_dt({"dt": 0.2}, None) == 0.2 and model_dt({"dt": 0.2}, 0.2) == 0.2
    with pytest.raises(ValueError, match="recorded at dt=0.2"):
        model_dt({"dt": 0.2}, 0.1)
    assert model_dt({}, 0.05) == 0.05 and capsys.readouterr().err == ""
    assert model_dt({}, None) == 0.1
    assert "pass --dt" in capsys.readouterr().err


def test_a_measured_camera_range_is_recorded_at_export_or_stamped_after(
    exported: tuple[Path, VelocityNet, dict], tmp_path: Path
) -> None:
    """`vtr export --camera-range` writes the range the model was measured to work in; a model measured after
    its export gets it stamped (fp32 and int8 twin), its graph and outputs untouched."""
    import shutil

    from vtr.export.provenance import stamp_camera_range
    from vtr.runtime.model_meta import CameraRange

    def meta(p: Path) -> ModelMeta:
        return ModelMeta.from_props({q.key: q.value for q in onnx.load(p).metadata_props})

    rng = CameraRange((65.0, 105.0), (0.2, 0.45))
    path = tmp_path / "velocitynet.onnx"
    shutil.copy(exported[0], path)
    data = synthetic_dataset(frames=60, size=SIZE, episodes=3, seed=2)
    quantize_int8(path, int8_path(path), *calibration_pairs(data.images, data.episodes, count=8, seed=0))
    feeds = {
        INPUT_CURRENT: np.random.default_rng(1).random((2, 3, SIZE, SIZE), dtype=np.float32),
        INPUT_SUBGOAL: np.random.default_rng(2).random((2, 3, SIZE, SIZE), dtype=np.float32),
    }
    before = {p: ort.InferenceSession(str(p)).run(None, feeds)[0] for p in (path, int8_path(path))}
    assert meta(path).camera_range is None
    assert stamp_camera_range(path, rng) == [path, int8_path(path)]
    for p, out in before.items():
        assert meta(p).camera_range == rng and meta(p).camera_fov_deg == meta(exported[0]).camera_fov_deg
        assert np.array_equal(ort.InferenceSession(str(p)).run(None, feeds)[0], out)
    with pytest.raises(ValueError, match="is not FOV0-FOV1,H0-H1"):
        ExportConfig(checkpoint="x.pt", out="y.onnx", camera_range="65,0.3")
    net = _velocitynet()
    ckpt = tmp_path / "velocitynet.pt"
    save_checkpoint(
        {
            "kind": "velocitynet",
            "model_config": to_dict(net.cfg),
            "state_dict": net.state_dict(),
            "data_meta": {"dt": 0.1},
        },
        ckpt,
    )
    out = tmp_path / "ranged.onnx"
    export_run(ExportConfig(checkpoint=str(ckpt), out=str(out), camera_range="65-105,0.2-0.45"))
    assert meta(out).camera_range == rng and meta(out).camera_fov_deg == 90.0
