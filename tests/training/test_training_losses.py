"""The offline MPC loss against a hand computation of the paper's equations, and ViewNet's L1 loss."""

from __future__ import annotations

import pytest
import torch

from vtr.training.config import MPCLossConfig, VelocityNetConfig, ViewNetConfig
from vtr.training.losses import mpc_loss, viewnet_loss
from vtr.training.models import VelocityNet, ViewNet

# Pass-1 and pass-2 velocities of the stub VelocityNet: rows (v, w), columns n = 1, 2.
U1 = torch.tensor([[0.2, 0.1], [0.3, -0.4]])
U2 = torch.tensor([[-0.1, -0.3], [-0.5, 0.2]])


def stub_velocitynet(current: torch.Tensor, subgoal: torch.Tensor) -> torch.Tensor:
    """Returns U1 when starting from the dark frame I_i (pass 1), U2 from the bright I_{i+2} (pass 2)."""
    first = current.flatten(1).mean(1) < 0.5  # (B,)
    return torch.where(first[:, None, None], U1, U2)  # (B, 2, N)


def stub_viewnet(image: torch.Tensor, velocity: torch.Tensor) -> torch.Tensor:
    """Brightens every pixel by v: the predicted image is I + v."""
    return image + velocity[:, 0, None, None, None]


def _example() -> tuple[torch.Tensor, torch.Tensor]:
    frames = torch.stack([torch.full((3, 2, 2), x) for x in (0.1, 0.5, 0.9)])[None]  # (1, 3, 3, 2, 2)
    commands = torch.tensor([[[0.25, 0.5], [0.15, -0.2]]])  # (1, N=2, 2): c_i, c_{i+1}
    return frames, commands


def test_mpc_loss_matches_the_papers_equations_by_hand() -> None:
    frames, commands = _example()
    loss, parts = mpc_loss(stub_velocitynet, stub_viewnet, frames, commands, MPCLossConfig(w1=0.8, w2=0.3))
    # Pass 1 from I_i = 0.1: I_p1 = 0.3 (target I_{i+1} = 0.5), I_p2 = 0.4 (target I_{i+2} = 0.9).
    j_img1 = (abs(0.5 - 0.3) + abs(0.9 - 0.4)) / 2
    # J_vel1 = 1/N sum_n (v_{c,i-1+n} - v_n)^2 + (w_{c,i-1+n} - w_n)^2
    j_vel1 = ((0.25 - 0.2) ** 2 + (0.5 - 0.3) ** 2 + (0.15 - 0.1) ** 2 + (-0.2 + 0.4) ** 2) / 2
    # Pass 2 from I_{i+2} = 0.9: I_p1 = 0.8 (target I_{i+1} = 0.5), I_p2 = 0.5 (target I_i = 0.1).
    j_img2 = (abs(0.5 - 0.8) + abs(0.1 - 0.5)) / 2
    # J_vel2 = 1/N sum_n (v_{c,i+2-n} + v_n)^2 + (w_{c,i+2-n} + w_n)^2
    j_vel2 = ((0.15 - 0.1) ** 2 + (-0.2 - 0.5) ** 2 + (0.25 - 0.3) ** 2 + (0.5 + 0.2) ** 2) / 2
    j1, j2 = 0.8 * j_img1 + 0.3 * j_vel1, 0.8 * j_img2 + 0.3 * j_vel2
    assert parts["img1"].item() == pytest.approx(j_img1, abs=1e-6)
    assert parts["vel1"].item() == pytest.approx(j_vel1, abs=1e-6)
    assert parts["img2"].item() == pytest.approx(j_img2, abs=1e-6)
    assert parts["vel2"].item() == pytest.approx(j_vel2, abs=1e-6)
    assert loss.item() == pytest.approx(0.5 * (j1 + j2), abs=1e-6)
    assert loss.item() == pytest.approx(0.36025, abs=1e-6)


def test_mpc_loss_batches_examples_independently() -> None:
    frames, commands = _example()
    single, _ = mpc_loss(stub_velocitynet, stub_viewnet, frames, commands, MPCLossConfig())
    double, _ = mpc_loss(
        stub_velocitynet,
        stub_viewnet,
        frames.repeat(2, 1, 1, 1, 1),
        commands.repeat(2, 1, 1),
        MPCLossConfig(),
    )
    assert double.item() == pytest.approx(single.item(), abs=1e-7)


def test_mpc_loss_rejects_a_window_of_the_wrong_length() -> None:
    frames, commands = _example()
    with pytest.raises(ValueError, match="N=3"):
        mpc_loss(stub_velocitynet, stub_viewnet, frames, commands, MPCLossConfig(horizon=3))


def test_gradient_reaches_velocitynet_through_a_frozen_viewnet() -> None:
    torch.manual_seed(0)
    vcfg = ViewNetConfig(
        image_size=32, encoder_channels=(4,) * 8, decoder_channels=(4, 4), flow_resolution=16
    )
    viewnet = ViewNet(vcfg).eval().requires_grad_(False)
    torch.nn.init.normal_(viewnet.flow.weight, std=0.1)  # a non-trivial flow, so images depend on u
    velnet = VelocityNet(VelocityNetConfig(image_size=32, channels=(4,) * 7))
    frames = torch.rand(3, 3, 3, 32, 32)
    commands = torch.rand(3, 2, 2) - 0.5
    loss, _ = mpc_loss(velnet, viewnet, frames, commands, MPCLossConfig(w1=1.0, w2=0.0))
    loss.backward()
    assert velnet.head.weight.grad is not None and velnet.head.weight.grad.abs().sum() > 0
    assert all(p.grad is None for p in viewnet.parameters())


def test_viewnet_loss_uses_forward_and_reversed_pairs() -> None:
    frames, commands = _example()
    pair = frames[:, :2]  # I_i = 0.1, I_{i+1} = 0.5
    # forward: 0.1 + 0.25 -> 0.35 vs 0.5 (0.15); reversed: 0.5 - 0.25 -> 0.25 vs 0.1 (0.15)
    loss = viewnet_loss(stub_viewnet, pair, commands[:, 0])
    assert loss.item() == pytest.approx(0.15, abs=1e-6)
