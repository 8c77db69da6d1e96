"""The floor-consistency term: a floor laid again must not change VelocityNet's command (issue 20).

The appearance swap (training.appearances) gives swapped pairs the true commands as labels, but those labels
are noisy (the driver's commands) and weighted like any other pair, and a handful of floor versions a house is
little variety: the shipped model's first command moved by 0.24 m/s RMS on the re-coloured floor
(studies/floor_probe.py). This term says directly what a repeat needs: VelocityNet(current in another
appearance, subgoal) equals VelocityNet(current, subgoal), the matched pair's output held fixed as the target
(the MPC loss keeps that one right). The current side changes, as in a repeat on a re-laid floor. Half of the
other-appearance images are re-coloured at random where they differ from the recorded one (the floor that was
laid again, sometimes walls), so every step shows floor colours no collection drew.
"""

from __future__ import annotations

import torch

#: A pixel differs between the appearances when a channel moves by more than this (images in [0, 1]).
CHANGED = 0.03
#: Per-channel gain and offset ranges of the random re-colouring, and the share of images re-coloured.
GAIN, OFFSET, RECOLOUR_SHARE = (0.5, 1.5), (-0.2, 0.2), 0.5


def _uniform(shape: tuple[int, ...], bounds: tuple[float, float], gen: torch.Generator) -> torch.Tensor:
    return bounds[0] + (bounds[1] - bounds[0]) * torch.rand(shape, generator=gen)


def recolour_changed(recorded: torch.Tensor, other: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
    """``other`` (B, 3, H, W) with the pixels that differ from ``recorded`` re-coloured in a share of the
    images (RECOLOUR_SHARE): channels shuffled, then a random gain and offset per channel."""
    b = other.shape[0]
    changed = (other - recorded).abs().amax(dim=1, keepdim=True) > CHANGED  # (B, 1, H, W)
    perm = torch.stack([torch.randperm(3, generator=gen) for _ in range(b)])  # (B, 3)
    shuffled = torch.gather(other, 1, perm[:, :, None, None].to(other.device).expand_as(other))
    gain = _uniform((b, 3, 1, 1), GAIN, gen).to(other.device)
    offset = _uniform((b, 3, 1, 1), OFFSET, gen).to(other.device)
    pick = (torch.rand(b, generator=gen) < RECOLOUR_SHARE).view(b, 1, 1, 1).to(other.device)
    return torch.where(changed & pick, (shuffled * gain + offset).clamp(0, 1), other)


def consistency_pairs(
    frames: torch.Tensor, other: torch.Tensor, count: int, horizon: int, gen: torch.Generator
) -> tuple[torch.Tensor, torch.Tensor]:
    """(views, goals), each (2 count, 3, H, W), from the first ``count`` windows (B, L, 3, H, W) in both
    appearances: the current frame in the other appearance first, then the recorded one, both against the
    recorded subgoal ``horizon`` frames on."""
    current, goal = frames[:count, 0], frames[:count, horizon]
    changed = recolour_changed(current, other[:count, 0], gen)
    return torch.cat([changed, current]), torch.cat([goal, goal])


def consistency_error(u: torch.Tensor) -> torch.Tensor:
    """VelocityNet's (2 count, 2, N) output on ``consistency_pairs`` -> the mean squared change of the
    command (the paper's J_vel form) against the matched pair's output, which is not trained by this term."""
    changed, matched = u.chunk(2)
    return (changed - matched.detach()).pow(2).sum(dim=1).mean()
