"""Photometric augmentation and the input pipeline VelocityNet is trained through."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch
import torch.nn.functional as F  # noqa: N812

from vtr.runtime.preprocess import STANDARDISED, normalise
from vtr.training.augment import AugmentConfig, InputPipeline, _uniform, photometric

OFF = AugmentConfig(
    brightness=(1, 1),
    contrast=(1, 1),
    gamma=(1, 1),
    colour=(1, 1),
    side_probability=0,
    blur_probability=0,
    noise_std=(0, 0),
    occluder_probability=0,
)


def images(b: int = 6, seed: int = 0) -> torch.Tensor:
    return torch.rand(b, 3, 16, 16, generator=torch.Generator().manual_seed(seed)) * 0.6 + 0.2


def test_augmentation_keeps_shape_and_range_and_is_reproducible():
    x = images()
    a = photometric(x, AugmentConfig(), torch.Generator().manual_seed(1))
    b = photometric(x, AugmentConfig(), torch.Generator().manual_seed(1))
    c = photometric(x, AugmentConfig(), torch.Generator().manual_seed(2))
    assert a.shape == x.shape and a.dtype == x.dtype and 0 <= a.min() and a.max() <= 1
    assert torch.equal(a, b) and not torch.equal(a, c)
    assert torch.allclose(photometric(x, OFF, torch.Generator()), x, atol=1e-6)  # every op off: identity


def test_each_image_gets_its_own_light():
    x = images(1).expand(8, -1, -1, -1)
    cfg = AugmentConfig(side_probability=0, blur_probability=0, noise_std=(0, 0), occluder_probability=0)
    means = photometric(x, cfg, torch.Generator().manual_seed(0)).mean(dim=(1, 2, 3))
    assert means.std() > 0.02  # brightness, contrast, gamma and colour differ per image


def test_occluder_paints_one_rectangle_of_one_colour():
    cfg = replace(OFF, occluder_probability=1.0, occluder_size=(0.5, 0.5))
    x = images(4)
    out = photometric(x, cfg, torch.Generator().manual_seed(3))
    changed = ((out - x).abs() > 1e-5).any(dim=1)  # (B, H, W); elsewhere only float rounding
    assert (changed.sum(dim=(1, 2)) <= 64).all() and (changed.sum(dim=(1, 2)) > 40).all()  # ~8x8 of 16x16


def test_side_darker_darkens_one_edge():
    cfg = replace(OFF, side_probability=1.0, side_low=(0.5, 0.5))
    x = torch.full((4, 3, 8, 8), 0.8)
    out = photometric(x, cfg, torch.Generator().manual_seed(0))
    edges = torch.stack([out[..., 0].mean(dim=(1, 2)), out[..., -1].mean(dim=(1, 2))], 1)  # (B, 2)
    assert torch.allclose(edges.min(dim=1).values, torch.tensor(0.4)) and torch.allclose(
        edges.max(dim=1).values, torch.tensor(0.8)
    )


class Echo(torch.nn.Module):
    def forward(self, current: torch.Tensor, subgoal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return current, subgoal


def test_input_pipeline_is_the_network_by_default_and_normalises_like_the_runtime():
    net, x, y = Echo(), images(2, 1), images(2, 2)
    cur, sub = InputPipeline(net)(x, y)
    assert cur is x and sub is y
    cur, sub = InputPipeline(net, STANDARDISED)(x, y)
    assert torch.allclose(cur, normalise(x, STANDARDISED)) and torch.allclose(sub, normalise(y, STANDARDISED))


def test_input_pipeline_augments_only_in_training_and_each_input_independently():
    net = Echo()
    x = images(2)
    pipe = InputPipeline(net, augment=AugmentConfig(), gen=torch.Generator().manual_seed(0))
    cur, sub = pipe(x, x)
    assert not torch.equal(cur, x) and not torch.equal(cur, sub)
    net.eval()
    cur, sub = pipe(x, x)
    assert cur is x and sub is x


def test_augment_config_validation():
    with pytest.raises(ValueError, match="brightness"):
        AugmentConfig(brightness=(1.5, 0.6))
    with pytest.raises(ValueError, match="occluder_probability"):
        AugmentConfig(occluder_probability=2.0)


def test_sensor_augmentation_is_deterministic_per_seed_and_off_by_default():
    from vtr.training.augment import sensor

    x = images(6, seed=3)
    on = AugmentConfig(sensor_probability=1.0, blur_shift_px=(2.0, 4.0), k1=(-0.25, -0.1))
    a = sensor(x, on, torch.Generator().manual_seed(5))
    b = sensor(x, on, torch.Generator().manual_seed(5))
    c = sensor(x, on, torch.Generator().manual_seed(6))
    assert a.shape == x.shape and a.dtype == x.dtype and 0 <= a.min() and a.max() <= 1
    assert torch.equal(a, b) and not torch.equal(a, c)
    assert (a - x).abs().mean(dim=(1, 2, 3)).min() > 0.01  # every image changed
    assert torch.equal(sensor(x, AugmentConfig(), torch.Generator().manual_seed(5)), x)  # probability 0
    with pytest.raises(ValueError, match="k1"):
        AugmentConfig(k1=(-0.9, 0.0))


def every_image(images: torch.Tensor, cfg: AugmentConfig, gen: torch.Generator) -> torch.Tensor:
    """The reference: photometric() as it was written first, every op on every image and ``torch.where``
    keeping the chosen ones (3x the work on a training batch). The same draws in the same order."""
    b, c, h, w = images.shape
    per_image = (b, 1, 1, 1)
    x = images.float() * _uniform(b, cfg.brightness, gen, images.device).view(per_image)
    mean = x.mean(dim=(1, 2, 3), keepdim=True)
    x = (x - mean) * _uniform(b, cfg.contrast, gen, x.device).view(per_image) + mean
    x = x.clamp(0, 1) ** _uniform(b, cfg.gamma, gen, x.device).view(per_image)
    x = x * _uniform(b * c, cfg.colour, gen, x.device).view(b, c, 1, 1)
    side = torch.rand(b, generator=gen) < cfg.side_probability
    if side.any():
        low = _uniform(b, cfg.side_low, gen, x.device).view(b, 1)
        t = torch.linspace(0, 1, w).view(1, w)
        flip = (torch.rand(b, generator=gen) < 0.5).view(b, 1)
        ramp = low + (1 - low) * torch.where(flip, 1 - t, t)
        x = torch.where(side.view(per_image), x * ramp.view(b, 1, 1, w), x)
    blur = torch.rand(b, generator=gen) < cfg.blur_probability
    if blur.any():
        blurred = F.avg_pool2d(x, 3, stride=1, padding=1, count_include_pad=False)
        x = torch.where(blur.view(per_image), blurred, x)
    x = x + _uniform(b, cfg.noise_std, gen, x.device).view(per_image) * torch.randn(x.shape, generator=gen)
    occ = torch.rand(b, generator=gen) < cfg.occluder_probability
    if occ.any():
        sizes = _uniform(2 * b, cfg.occluder_size, gen, x.device).view(b, 2)
        corners = torch.rand(b, 2, generator=gen)
        colours = torch.rand(b, c, generator=gen)
        rows, cols = torch.arange(h).view(1, h, 1), torch.arange(w).view(1, 1, w)
        hh, ww = (sizes[:, 0] * h).long().view(b, 1, 1), (sizes[:, 1] * w).long().view(b, 1, 1)
        top = (corners[:, 0] * (h - hh.view(b) + 1)).long().view(b, 1, 1)
        left = (corners[:, 1] * (w - ww.view(b) + 1)).long().view(b, 1, 1)
        inside = (rows >= top) & (rows < top + hh) & (cols >= left) & (cols < left + ww) & occ.view(b, 1, 1)
        x = torch.where(inside.unsqueeze(1), colours.view(b, c, 1, 1), x)
    return x.clamp(0, 1)


@pytest.mark.parametrize(
    "cfg",
    [
        AugmentConfig(),
        AugmentConfig(side_probability=1.0, blur_probability=1.0, occluder_probability=1.0),
        AugmentConfig(side_probability=0.0, blur_probability=0.0, occluder_probability=0.0),
    ],
)
def test_augmenting_the_chosen_images_only_gives_the_bits_of_augmenting_every_image(cfg: AugmentConfig):
    for seed in range(12):
        x = torch.rand(9 + seed, 3, 24, 40, generator=torch.Generator().manual_seed(100 + seed))
        before = x.clone()
        out = photometric(x, cfg, torch.Generator().manual_seed(seed))
        assert torch.equal(x, before)  # the input is not changed in place
        assert torch.equal(out, every_image(x, cfg, torch.Generator().manual_seed(seed)))
