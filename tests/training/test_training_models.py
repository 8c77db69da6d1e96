"""ViewNet and VelocityNet: shapes, bounds, the copy-baseline start, configs and presets."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vtr.runtime.preprocess import to_nchw
from vtr.training.config import PRESETS, TrainConfig, VelocityNetConfig, ViewNetConfig, get_preset
from vtr.training.models import VelocityNet, ViewNet
from vtr.training.windows import images_to_float


def _tiny_viewnet() -> ViewNet:
    return ViewNet(get_preset("tiny").viewnet)


def test_untrained_viewnet_copies_its_input() -> None:
    torch.manual_seed(0)
    net = _tiny_viewnet().eval()
    image = torch.rand(2, 3, 32, 32)
    out = net(image, torch.tensor([[0.5, -1.0], [0.1, 0.3]]))
    assert out.shape == (2, 3, 32, 32)
    assert torch.allclose(out, image, atol=1e-5)


def test_viewnet_shifts_the_image_when_the_flow_is_nonzero() -> None:
    net = _tiny_viewnet().eval()
    torch.nn.init.constant_(net.flow.bias, 0.0)
    with torch.no_grad():
        net.flow.bias[0] = 2.0 / 32  # one pixel to the right in normalised units
    image = torch.rand(1, 3, 32, 32)
    out = net(image, torch.zeros(1, 2))
    assert torch.allclose(out[..., :-1], image[..., 1:], atol=1e-5)


@pytest.mark.parametrize("horizon", [1, 2, 3])
def test_velocitynet_shape_and_bounds(horizon: int) -> None:
    cfg = VelocityNetConfig(image_size=32, channels=(4,) * 7, horizon=horizon, v_max=0.5, w_max=1.0)
    net = VelocityNet(cfg).eval()
    with torch.no_grad():
        net.head.bias.copy_(torch.linspace(-50, 50, 2 * horizon))  # saturate the tanh heads
    out = net(torch.rand(5, 3, 32, 32), torch.rand(5, 3, 32, 32))
    assert out.shape == (5, 2, horizon)
    assert out[:, 0].abs().max() <= 0.5 + 1e-6 and out[:, 1].abs().max() <= 1.0 + 1e-6
    assert out[:, 0].abs().max() > 0.49 and out[:, 1].abs().max() > 0.99


def test_velocitynet_distinguishes_current_from_subgoal() -> None:
    torch.manual_seed(0)
    net = VelocityNet(VelocityNetConfig(image_size=32, channels=(8,) * 7)).eval()
    a, b = torch.rand(1, 3, 32, 32), torch.rand(1, 3, 32, 32)
    assert not torch.allclose(net(a, b), net(b, a))


def test_every_preset_builds() -> None:
    for name in PRESETS:
        p = get_preset(name)
        assert p.velocitynet.horizon == p.loss.horizon == 2
        ViewNet(p.viewnet)
        VelocityNet(p.velocitynet)
    paper = get_preset("paper")
    assert paper.viewnet.encoder_channels[-1] == 512 and paper.viewnet.flow_resolution == 128


@pytest.mark.parametrize(
    ("cls", "kwargs", "match"),
    [
        (ViewNetConfig, {"encoder_channels": (4,) * 7}, "8 entries"),
        (ViewNetConfig, {"flow_resolution": 100}, "flow_resolution"),
        (VelocityNetConfig, {"horizon": 0}, "horizon"),
        (VelocityNetConfig, {"channels": (4, 4, 4, 4, 4, 4, -1)}, "channels"),
        (TrainConfig, {"lr": 0.0}, "lr"),
        (TrainConfig, {"device": "tpu"}, "tpu"),
        (TrainConfig, {"val_fraction": 1.5}, "val_fraction"),
    ],
)
def test_configs_name_the_bad_value(cls: type, kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        cls(**kwargs)


def test_unknown_preset_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="unknown preset 'huge'"):
        get_preset("huge")


def test_training_preprocessing_is_bit_identical_to_the_runtimes() -> None:
    images = np.random.default_rng(0).integers(0, 256, size=(3, 5, 7, 3), dtype=np.uint8)
    ours = images_to_float(torch.from_numpy(images)).numpy()
    assert ours.dtype == np.float32
    np.testing.assert_array_equal(ours, to_nchw(images))
