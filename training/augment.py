"""What VelocityNet's two inputs go through in training: photometric augmentation, then the runtime's own
normalisation (``runtime.preprocess.normalise``, the model's ``preprocessing``).

Between teach and repeat the light changes, so the subgoal and the current image are augmented
*independently* (different draws): the network learns to steer from geometry, not from brightness. ViewNet
and the MPC loss's image targets are not touched: the loss still compares clean predicted images with
clean recorded ones; only what VelocityNet sees is changed.

Per image (each op's parameters drawn per image): brightness gain, contrast about the image mean, gamma,
per-channel colour balance, one side darker (a horizontal gain ramp), a 3x3 blur, Gaussian sensor noise
and a rectangular occluder of random colour (a box, a person, a moved chair in front of the camera).

Then, with ``sensor_probability`` (0 by default: the shipped recipe is unchanged), a camera's sensor realism
through the simulator's own implementation (sim2d.sensor, numpy and OpenCV on the CPU): motion blur of a
random turn and drive during the exposure, radial lens distortion, JPEG compression; all drawn from the same
torch generator, so a seed gives the same images.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F  # noqa: N812
from torch import nn

from vtr.runtime.preprocess import PREPROCESSING, normalise


@dataclass(frozen=True)
class AugmentConfig:
    """Ranges of the photometric augmentation (uniform draws; (1, 1) or probability 0 turns an op off)."""

    brightness: tuple[float, float] = (0.6, 1.5)  # gain on every pixel
    contrast: tuple[float, float] = (0.7, 1.3)  # gain on the deviation from the image mean
    gamma: tuple[float, float] = (0.7, 1.4)  # x ** gamma
    colour: tuple[float, float] = (0.8, 1.2)  # per-channel gain
    side_probability: float = 0.3  # chance of one side darker
    side_low: tuple[float, float] = (0.45, 0.9)  # gain at the dark edge (1 at the other)
    blur_probability: float = 0.2  # chance of a 3x3 box blur
    noise_std: tuple[float, float] = (0.0, 0.03)  # Gaussian sensor noise, in [0, 1] pixel units
    occluder_probability: float = 0.25  # chance of one rectangle of random colour
    occluder_size: tuple[float, float] = (0.1, 0.35)  # its sides, as fractions of the image's
    sensor_probability: float = 0.0  # chance of the sensor ops below (sim2d.sensor) for an image
    blur_shift_px: tuple[float, float] = (0.0, 4.0)  # motion blur: sideways slide (either way), pixels
    blur_zoom: tuple[float, float] = (0.0, 0.03)  # motion blur: growth about the centre (driving forward)
    k1: tuple[float, float] = (-0.25, 0.05)  # radial distortion (negative: barrel)
    jpeg_probability: float = 0.5  # of those images, the chance of JPEG compression ...
    jpeg_quality: tuple[float, float] = (25.0, 90.0)  # ... at a quality in this range

    def __post_init__(self) -> None:
        for name in ("brightness", "contrast", "gamma", "colour", "side_low", "noise_std", "occluder_size"):
            lo, hi = getattr(self, name)
            if not 0 <= lo <= hi:
                raise ValueError(f"AugmentConfig.{name} must be a range 0 <= low <= high, got {(lo, hi)}")
        for name in ("blur_shift_px", "blur_zoom", "jpeg_quality"):
            lo, hi = getattr(self, name)
            if not 0 <= lo <= hi:
                raise ValueError(f"AugmentConfig.{name} must be a range 0 <= low <= high, got {(lo, hi)}")
        if not -0.5 <= self.k1[0] <= self.k1[1] <= 0.5:
            raise ValueError(f"AugmentConfig.k1 must be a range within [-0.5, 0.5], got {self.k1}")
        if self.jpeg_quality[1] > 100 or self.jpeg_quality[0] < 1:
            raise ValueError(f"AugmentConfig.jpeg_quality must lie within 1..100, got {self.jpeg_quality}")
        for name in (
            "side_probability",
            "blur_probability",
            "occluder_probability",
            "sensor_probability",
            "jpeg_probability",
        ):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"AugmentConfig.{name} must be in [0, 1], got {getattr(self, name)}")
        if self.occluder_size[1] > 1 or self.side_low[1] > 1:
            raise ValueError("AugmentConfig.occluder_size and side_low must be at most 1")


def _uniform(n: int, bounds: tuple[float, float], gen: torch.Generator, device: torch.device) -> torch.Tensor:
    lo, hi = bounds
    return (lo + (hi - lo) * torch.rand(n, generator=gen)).to(device)


def _gaussian(shape: torch.Size, gen: torch.Generator, device: torch.device) -> torch.Tensor:
    """Standard normal draws of ``shape`` on ``device``: on the CPU from ``gen`` itself, elsewhere from a device
    generator seeded from ``gen``. The sensor noise is the augmentation's one large draw (the MPC loss's 256
    inputs at batch 64: 50 MB a step, about 0.1 s of a loaded CPU core); drawn on the host and copied, it kept
    a GPU step waiting on the host (session 12's lease: ~73 ms a step for a default-size and a 10x larger net)."""
    if device.type == "cpu":
        return torch.randn(shape, generator=gen)
    seed = int(torch.randint(0, 2**62, (1,), generator=gen))
    return torch.randn(shape, generator=torch.Generator(device=device).manual_seed(seed), device=device)


def photometric(images: torch.Tensor, cfg: AugmentConfig, gen: torch.Generator) -> torch.Tensor:
    """float (B, 3, H, W) in [0, 1] -> the same shape, augmented per image (see the module docstring).

    One new tensor, changed in place, and the ops drawn for some images (one side darker, the blur, the
    occluder) run on those images only: a batch's step on 2 CPU cores spent a third of its time here when
    every op ran on every image and ``torch.where`` kept the chosen ones. The draws and every value are
    those of that formulation (tests/training/test_augment.py keeps it as the reference)."""
    b, c, h, w = images.shape
    dev = images.device
    per_image = (b, 1, 1, 1)
    x = images.float() * _uniform(b, cfg.brightness, gen, dev).view(per_image)  # a new tensor: images stay
    mean = x.mean(dim=(1, 2, 3), keepdim=True)
    x.sub_(mean).mul_(_uniform(b, cfg.contrast, gen, dev).view(per_image)).add_(mean)
    x.clamp_(0, 1).pow_(_uniform(b, cfg.gamma, gen, dev).view(per_image))
    x.mul_(_uniform(b * c, cfg.colour, gen, dev).view(b, c, 1, 1))
    side = torch.rand(b, generator=gen) < cfg.side_probability
    if side.any():
        low = _uniform(b, cfg.side_low, gen, dev).view(b, 1)
        t = torch.linspace(0, 1, w, device=dev).view(1, w)
        flip = (torch.rand(b, generator=gen) < 0.5).to(dev).view(b, 1)
        ramp = low + (1 - low) * torch.where(flip, 1 - t, t)  # (B, W)
        chosen = side.nonzero().flatten().to(dev)
        x[chosen] = x[chosen] * ramp[chosen].view(-1, 1, 1, w)
    blur = torch.rand(b, generator=gen) < cfg.blur_probability
    if blur.any():
        chosen = blur.nonzero().flatten().to(dev)
        x[chosen] = F.avg_pool2d(x[chosen], 3, stride=1, padding=1, count_include_pad=False)
    std = _uniform(b, cfg.noise_std, gen, dev).view(per_image)
    x.add_(std * _gaussian(x.shape, gen, dev))
    occ = torch.rand(b, generator=gen) < cfg.occluder_probability
    if occ.any():
        sizes = _uniform(2 * b, cfg.occluder_size, gen, torch.device("cpu")).view(b, 2)
        corners = torch.rand(b, 2, generator=gen)
        colours = torch.rand(b, c, generator=gen).to(dev)
        hh, ww = (sizes[:, 0] * h).long(), (sizes[:, 1] * w).long()
        tops = (corners[:, 0] * (h - hh + 1)).long()
        lefts = (corners[:, 1] * (w - ww + 1)).long()
        for i in occ.nonzero().flatten().tolist():
            top, left = int(tops[i]), int(lefts[i])
            x[i, :, top : top + int(hh[i]), left : left + int(ww[i])] = colours[i].view(c, 1, 1)
    return x.clamp_(0, 1).to(images.dtype)


def sensor(images: torch.Tensor, cfg: AugmentConfig, gen: torch.Generator) -> torch.Tensor:
    """float (B, 3, H, W) in [0, 1] -> the same, with sim2d.sensor's motion blur, lens distortion and JPEG
    applied to each image with ``cfg.sensor_probability`` (parameters drawn per image from ``gen``)."""
    from vtr.sim2d.sensor import jpeg, motion_blur, radial_distortion

    b = images.shape[0]
    chosen = torch.rand(b, generator=gen) < cfg.sensor_probability
    draws = (
        torch.rand(b, 5, generator=gen).double().numpy()
    )  # drawn for every image: the stream stays aligned
    if not chosen.any():
        return images
    out = images.clone()
    for i in torch.nonzero(chosen).flatten().tolist():
        u = draws[i]
        img = (images[i].detach().float().clamp(0, 1).permute(1, 2, 0).cpu().numpy() * 255 + 0.5).astype(
            "uint8"
        )
        shift = (cfg.blur_shift_px[0] + (cfg.blur_shift_px[1] - cfg.blur_shift_px[0]) * u[0]) * (
            1 if u[1] < 0.5 else -1
        )
        zoom = cfg.blur_zoom[0] + (cfg.blur_zoom[1] - cfg.blur_zoom[0]) * u[2]
        img = motion_blur(img, shift, zoom)
        img = radial_distortion(
            img, round(cfg.k1[0] + (cfg.k1[1] - cfg.k1[0]) * u[3], 3)
        )  # few distinct maps
        if u[4] < cfg.jpeg_probability:
            q = cfg.jpeg_quality[0] + (cfg.jpeg_quality[1] - cfg.jpeg_quality[0]) * u[4] / max(
                cfg.jpeg_probability, 1e-9
            )
            img = jpeg(img, int(round(q)))
        out[i] = torch.from_numpy(img).to(images.device, torch.float32).permute(2, 0, 1) / 255.0
    return out.to(images.dtype)


class InputPipeline(nn.Module):
    """VelocityNet as the MPC loss sees it in training: both inputs augmented (while ``net`` is in training
    mode and ``augment`` is given) and normalised as the runtime will (``preprocessing``).

    With the default preprocessing and no augmentation it is exactly ``net``. Built around the network per
    use (cheap), so the network itself, its checkpoint and its ONNX export stay unchanged.
    """

    def __init__(
        self,
        net: nn.Module,
        preprocessing: str = PREPROCESSING,
        augment: AugmentConfig | None = None,
        gen: torch.Generator | None = None,
    ) -> None:
        super().__init__()
        self.net, self.preprocessing, self.augment = net, preprocessing, augment
        self.gen = gen if gen is not None else torch.Generator().manual_seed(0)

    def forward(self, current: torch.Tensor, subgoal: torch.Tensor) -> torch.Tensor:
        # current, subgoal: (B, 3, H, W) in [0, 1] -> (B, 2, N)
        if self.augment is not None and self.net.training:
            current = photometric(current, self.augment, self.gen)
            subgoal = photometric(subgoal, self.augment, self.gen)
            if self.augment.sensor_probability > 0:
                current = sensor(current, self.augment, self.gen)
                subgoal = sensor(subgoal, self.augment, self.gen)
        return self.net(normalise(current, self.preprocessing), normalise(subgoal, self.preprocessing))
