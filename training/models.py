"""ViewNet (future image prediction) and VelocityNet (the offline-MPC policy).

Only layers that both onnxruntime and OpenCV's cv2.dnn run are used in VelocityNet: Conv, BatchNorm
(folded into the conv on export), LeakyReLU, Concat, GlobalAveragePool, Reshape, Tanh and Mul.
ViewNet also uses ConvTranspose, Resize and GridSample (ONNX opset >= 16).
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn
from torch.nn import functional as F

from vtr.training.config import VelocityNetConfig, ViewNetConfig


def _conv_bn_act(c_in: int, c_out: int, stride: int, slope: float, kernel: int = 3) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(c_in, c_out, kernel, stride=stride, padding=kernel // 2, bias=False),
        nn.BatchNorm2d(c_out),
        nn.LeakyReLU(slope),
    )


def _encoder(c_in: int, channels: tuple[int, ...], slope: float) -> nn.Sequential:
    """8 convs: 7 of stride 2 (128 -> 1 pixel) then a 1x1 to the feature size, all BN + LeakyReLU."""
    layers: list[nn.Module] = []
    for i, c_out in enumerate(channels):
        last = i == len(channels) - 1
        layers.append(
            _conv_bn_act(c_in, c_out, stride=1 if last else 2, slope=slope, kernel=1 if last else 3)
        )
        c_in = c_out
    return nn.Sequential(*layers)


class ViewNet(nn.Module):
    """Predicts the image seen after applying (v, w) for one control step.

    The decoder outputs a flow offset that is added to the identity sampling grid, and the input image
    is resampled with it (``grid_sample``). The offset's last layer starts at zero, so an untrained
    ViewNet reproduces the input image: it starts at the copy-the-input baseline and learns the motion.
    The command joins the image feature scaled by ``cfg.velocity_gain``: at a comparable size, so that
    the decoder's input carries the motion it must learn rather than image-only noise (config.py).
    """

    def __init__(self, cfg: ViewNetConfig) -> None:
        super().__init__()
        self.cfg = cfg
        slope = cfg.leaky_slope
        self.encoder = _encoder(3, cfg.encoder_channels, slope)
        feat = cfg.encoder_channels[-1]
        dec = cfg.decoder_channels
        # (feature + velocity) at 1x1 -> dec[0] x 4 x 4
        self.stem = nn.Sequential(
            nn.ConvTranspose2d(feat + 2, dec[0], 4, bias=False), nn.BatchNorm2d(dec[0]), nn.LeakyReLU(slope)
        )
        ups: list[nn.Module] = []
        for c_in, c_out in zip(dec, dec[1:] + (dec[-1],), strict=True):
            ups += [
                nn.ConvTranspose2d(c_in, c_out, 4, stride=2, padding=1, bias=False),
                nn.BatchNorm2d(c_out),
                nn.LeakyReLU(slope),
            ]
        self.up = nn.Sequential(*ups)
        self.flow = nn.Conv2d(dec[-1], 2, 3, padding=1)
        nn.init.zeros_(self.flow.weight)
        nn.init.zeros_(self.flow.bias)
        scale = [cfg.velocity_gain / cfg.v_max, cfg.velocity_gain / cfg.w_max]
        self.register_buffer("vel_scale", torch.tensor(scale), persistent=False)
        self.register_buffer("identity", self._identity_grid(cfg.image_size), persistent=False)

    @staticmethod
    def _identity_grid(size: int) -> torch.Tensor:
        # Pixel centres in grid_sample's normalised coordinates (align_corners=False).
        lin = (torch.arange(size, dtype=torch.float32) + 0.5) * (2.0 / size) - 1.0
        yy, xx = torch.meshgrid(lin, lin, indexing="ij")
        return torch.stack([xx, yy], dim=-1)[None]  # (1, H, W, 2), last dim = (x, y)

    def flow_offset(self, image: torch.Tensor, velocity: torch.Tensor) -> torch.Tensor:
        """(B, 3, H, W), (B, 2) -> flow offset (B, 2, H, W) in normalised grid units."""
        feat = self.encoder(image)  # (B, F, 1, 1)
        vel = (velocity * self.vel_scale)[:, :, None, None]  # (B, 2, 1, 1), in [-gain, gain]
        x = self.stem(torch.cat([feat, vel], dim=1))  # (B, dec0, 4, 4)
        x = self.up(x)  # (B, decL, R, R), R = flow_resolution
        flow = self.flow(x)  # (B, 2, R, R)
        if self.cfg.flow_resolution != self.cfg.image_size:
            size = (self.cfg.image_size, self.cfg.image_size)
            flow = F.interpolate(flow, size=size, mode="bilinear", align_corners=False)
        return flow  # (B, 2, H, W)

    def forward(self, image: torch.Tensor, velocity: torch.Tensor) -> torch.Tensor:
        """image (B, 3, H, W) in [0, 1], velocity (B, 2) = (v, w) -> predicted image (B, 3, H, W)."""
        flow = self.flow_offset(image, velocity)  # (B, 2, H, W)
        grid = self.identity + flow.permute(0, 2, 3, 1)  # (B, H, W, 2)
        return F.grid_sample(image, grid, mode="bilinear", padding_mode="border", align_corners=False)


class VelocityNet(nn.Module):
    """(current, subgoal) images -> velocities (B, 2, N): row 0 = v (m/s), row 1 = w (rad/s)."""

    def __init__(self, cfg: VelocityNetConfig) -> None:
        super().__init__()
        self.cfg = cfg
        layers: list[nn.Module] = []
        c_in = 6
        for c_out in cfg.channels:
            layers.append(_conv_bn_act(c_in, c_out, stride=2, slope=cfg.leaky_slope))
            c_in = c_out
        self.features = nn.Sequential(*layers)
        # The 8th conv: no BN, no activation; its 2N outputs are split into the v and w vectors.
        self.head = nn.Conv2d(c_in, 2 * cfg.horizon, 1)
        self.pool = nn.AdaptiveAvgPool2d(1)

    def forward(self, current: torch.Tensor, subgoal: torch.Tensor) -> torch.Tensor:
        """current, subgoal (B, 3, H, W) float in [0, 1] (runtime.preprocess.to_nchw) -> (B, 2, N)."""
        n = self.cfg.horizon
        x = torch.cat([current, subgoal], dim=1)  # (B, 6, H, W)
        x = self.features(x)  # (B, C, H/128, W/128)
        x = self.pool(self.head(x))  # (B, 2N, 1, 1)
        x = torch.tanh(x.reshape(-1, 2, n))  # (B, 2, N)
        v, w = torch.split(x, 1, dim=1)  # (B, 1, N) each
        # Scalar Muls and a Concat rather than a broadcast constant: both ONNX runtimes take these.
        return torch.cat([v * self.cfg.v_max, w * self.cfg.w_max], dim=1)  # (B, 2, N)


def build_model(kind: str, cfg: Any) -> nn.Module:
    if kind == "viewnet":
        return ViewNet(cfg)
    if kind == "velocitynet":
        return VelocityNet(cfg)
    raise ValueError(f"unknown model kind {kind!r}")
