"""The losses: ViewNet's L1 next-frame loss and the paper's offline MPC loss for VelocityNet.

Offline MPC loss (paper, "Training VelocityNet"), for a window of N + 1 consecutive frames
I_i .. I_{i+N} with the commands c_i .. c_{i+N-1} that moved the robot between them:

* pass j = 1: u = VelocityNet(I_i, I_{i+N}); ViewNet rolls u forward from I_i:
  I_p1 = ViewNet(I_i, u_1), I_pn = ViewNet(I_p(n-1), u_n). Targets I_{i+n}, commands c_{i-1+n}.
* pass j = 2 (reversed): u = VelocityNet(I_{i+N}, I_i), rolled from I_{i+N}. Targets I_{i+N-n},
  commands -c_{i+N-n} (the reversed sequence, negated: driving (-v, -w) retraces the arc).
* J_img_j = 1/N sum_n MAE(target_n, I_pn)   (the paper's 1/(2 n_pix) sum |.| for N = 2)
  J_vel_j = 1/N sum_n ((v_c,n - v_n)^2 + (w_c,n - w_n)^2)
  J_j = w1 J_img_j + w2 J_vel_j,  J = 1/2 (J_1 + J_2).

For N = 2 (the paper's setting and our default) this is exactly equations (2)-(7) of the paper; for
N > 2 the window simply grows to N + 1 frames. Pixels are in [0, 1] (runtime.preprocess.to_nchw), and
MAE averages over channels and pixels as well as the batch.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from vtr.training.config import MPCLossConfig

VelocityFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]  # (B,3,H,W) x2 -> (B, 2, N)
ViewFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]  # (B,3,H,W), (B,2) -> (B,3,H,W)


def viewnet_loss(viewnet: ViewFn, frames: torch.Tensor, commands: torch.Tensor) -> torch.Tensor:
    """L1 next-frame loss on forward pairs and on reversed pairs.

    frames (B, 2, 3, H, W) = (I_i, I_{i+1}); commands (B, 2) = c_i. The reversed pair is
    (I_{i+1}, -c_i) -> I_i, which VelocityNet's second pass asks of ViewNet.
    """
    src = torch.cat([frames[:, 0], frames[:, 1]], dim=0)  # (2B, 3, H, W)
    dst = torch.cat([frames[:, 1], frames[:, 0]], dim=0)  # (2B, 3, H, W)
    vel = torch.cat([commands, -commands], dim=0)  # (2B, 2)
    return (viewnet(src, vel) - dst).abs().mean()


def velocity_error(u: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """(B, 2, N) velocities against (B, 2, N) targets -> (B,): 1/N sum_n (dv^2 + dw^2), the paper's J_vel."""
    return (target - u).pow(2).sum(dim=1).mean(dim=1)


def mpc_loss(
    velocitynet: VelocityFn,
    viewnet: ViewFn,
    frames: torch.Tensor,
    commands: torch.Tensor,
    cfg: MPCLossConfig,
    goals: torch.Tensor | None = None,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """The paper's offline MPC loss.

    Both passes go through VelocityNet (and each ViewNet roll-out step) as one batch of 2B: one call
    per network per step, which DistributedDataParallel requires and which is faster.

    Args:
        velocitynet: (current, subgoal) -> (B, 2, N) velocities.
        viewnet: (image, (v, w)) -> predicted image; frozen, but gradients flow through it to u.
        frames: (B, N + 1, 3, H, W) consecutive frames I_i .. I_{i+N}.
        commands: (B, N, 2) commands c_i .. c_{i+N-1}, each (v, w).
        cfg: weights and horizon.
        goals: the frames VelocityNet's subgoals come from (default ``frames``): the same poses in another
            appearance teaches that the subgoal's floor may differ from the current one's (training.appearances).

    Returns:
        J and a dict of its parts (J1, J2, img1, img2, vel1, vel2, and u1 = pass-1 velocities).
    """
    n = cfg.horizon
    if frames.shape[1] != n + 1 or commands.shape[1:] != (n, 2):
        raise ValueError(
            f"MPC loss with N={n} needs frames (B, {n + 1}, 3, H, W) and commands (B, {n}, 2), "
            f"got {tuple(frames.shape)} and {tuple(commands.shape)}"
        )
    b = frames.shape[0]
    if goals is not None and goals.shape != frames.shape:
        raise ValueError(f"MPC loss goals {tuple(goals.shape)} differ from frames {tuple(frames.shape)}")
    goals = frames if goals is None else goals
    # Pass 1: I_i -> I_{i+N}; pass 2: I_{i+N} -> I_i. Stacked along the batch: (2B, ...).
    start = torch.cat([frames[:, 0], frames[:, n]], dim=0)  # (2B, 3, H, W)
    goal = torch.cat([goals[:, n], goals[:, 0]], dim=0)  # (2B, 3, H, W)
    u = velocitynet(start, goal)  # (2B, 2, N)
    if u.shape != (2 * b, 2, n):
        raise ValueError(f"VelocityNet returned shape {tuple(u.shape)}, expected ({2 * b}, 2, {n})")
    # Pass 1 targets I_{i+1} .. I_{i+N}; pass 2 targets I_{i+N-1} .. I_i.
    targets = [
        torch.cat([frames[:, k], frames[:, n - k]], dim=0) for k in range(1, n + 1)
    ]  # N x (2B, 3, H, W)
    # Pass 1 commands c_i .. c_{i+N-1}; pass 2 the reversed sequence negated: -c_{i+N-1} .. -c_i.
    cmd = torch.cat([commands, -commands.flip(1)], dim=0).transpose(1, 2)  # (2B, 2, N)
    image = start
    img_err = start.new_zeros(2 * b)
    for k in range(n):
        image = viewnet(image, u[:, :, k])  # (2B, 3, H, W)
        img_err = img_err + (targets[k] - image).abs().flatten(1).mean(dim=1)  # (2B,)
    img_err = img_err / n
    vel_err = velocity_error(u, cmd)  # (2B,)
    img1, img2 = img_err[:b].mean(), img_err[b:].mean()
    vel1, vel2 = vel_err[:b].mean(), vel_err[b:].mean()
    j1 = cfg.w1 * img1 + cfg.w2 * vel1
    j2 = cfg.w1 * img2 + cfg.w2 * vel2
    total = 0.5 * (j1 + j2)
    parts = {"J1": j1, "J2": j2, "img1": img1, "img2": img2, "vel1": vel1, "vel2": vel2, "u1": u[:b]}
    return total, parts
