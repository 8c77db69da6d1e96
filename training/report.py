"""Offline quality report on held-out episodes, each figure next to the baseline it must beat.

* ViewNet: L1 of the predicted next frame (forward pairs, and reversed pairs) against the
  "copy the input frame" baseline (predict I_{i+1} = I_i).
* VelocityNet: error of the first predicted command (v_1, w_1) against the recorded c_i on held-out
  windows, against the "always predict the mean training command" baseline.
Pixel errors are on the [0, 1] scale; ``*_255`` repeats them on the 0..255 scale of e_m.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from vtr.training.config import MAX_RATIO, MPCLossConfig
from vtr.training.losses import mpc_loss

if TYPE_CHECKING:
    from vtr.training.windows import Windows


class NoGainError(RuntimeError):
    """A stage's held-out result did not beat its baseline: the pipeline stops (exit 1) unless told to go on."""


def _ratio(model: float, baseline: float) -> float:
    return float(model / baseline) if baseline > 0 else float("nan")


@torch.no_grad()
def viewnet_report(
    viewnet: torch.nn.Module, windows: Windows, batch: int, amp: bool = False
) -> dict[str, Any]:
    viewnet.eval()
    fwd = rev = copy = 0.0
    count = 0
    device = next(viewnet.parameters()).device
    for starts in windows.val_batches(batch, None):
        frames, commands = windows.gather(starts)  # (B, 2, 3, H, W), (B, 1, 2)
        with torch.autocast("cuda", torch.bfloat16, enabled=amp and device.type == "cuda"):
            pred_f = viewnet(frames[:, 0], commands[:, 0]).float()
            pred_r = viewnet(frames[:, 1], -commands[:, 0]).float()
        b = len(starts)
        fwd += float((pred_f - frames[:, 1]).abs().mean()) * b
        rev += float((pred_r - frames[:, 0]).abs().mean()) * b
        copy += float((frames[:, 0] - frames[:, 1]).abs().mean()) * b
        count += b
    fwd, rev, copy = fwd / count, rev / count, copy / count
    return {
        "model": "viewnet",
        "held_out_pairs": count,
        "viewnet_l1": fwd,
        "viewnet_l1_reversed": rev,
        "copy_baseline_l1": copy,
        "viewnet_l1_255": fwd * 255,
        "copy_baseline_l1_255": copy * 255,
        "ratio_to_baseline": _ratio(fwd, copy),
        "beats_baseline": bool(fwd < copy and rev < copy),
    }


@torch.no_grad()
def velocitynet_report(
    velocitynet: torch.nn.Module,
    viewnet: torch.nn.Module,
    windows: Windows,
    loss_cfg: MPCLossConfig,
    batch: int,
    amp: bool = False,
) -> dict[str, Any]:
    velocitynet.eval()
    viewnet.eval()
    device = next(velocitynet.parameters()).device
    mean_cmd = torch.as_tensor(windows.mean_command, device=device)  # (2,)
    sq = torch.zeros(2, dtype=torch.float64)
    ab = torch.zeros(2, dtype=torch.float64)
    base_sq = torch.zeros(2, dtype=torch.float64)
    base_ab = torch.zeros(2, dtype=torch.float64)
    loss_sum = img_sum = 0.0
    count = 0
    for starts in windows.val_batches(batch, None):
        frames, commands = windows.gather(starts)  # (B, N+1, 3, H, W), (B, N, 2)
        with torch.autocast("cuda", torch.bfloat16, enabled=amp and device.type == "cuda"):
            loss, parts = mpc_loss(velocitynet, viewnet, frames, commands, loss_cfg)
        first = parts["u1"][:, :, 0].float()  # (B, 2) predicted (v_1, w_1)
        target = commands[:, 0]  # (B, 2) recorded c_i
        sq += (first - target).pow(2).sum(0).double().cpu()
        ab += (first - target).abs().sum(0).double().cpu()
        base_sq += (mean_cmd - target).pow(2).sum(0).double().cpu()
        base_ab += (mean_cmd - target).abs().sum(0).double().cpu()
        loss_sum += float(loss) * len(starts)
        img_sum += float(0.5 * (parts["img1"] + parts["img2"])) * len(starts)
        count += len(starts)
    mse, mae = (sq / count).numpy(), (ab / count).numpy()
    bmse, bmae = (base_sq / count).numpy(), (base_ab / count).numpy()
    return {
        "model": "velocitynet",
        "held_out_windows": count,
        "mse_first_command": float(mse.sum()),  # (dv^2 + dw^2), as in J_vel
        "mae_v": float(mae[0]),
        "mae_w": float(mae[1]),
        "mean_baseline_mse": float(bmse.sum()),
        "mean_baseline_mae_v": float(bmae[0]),
        "mean_baseline_mae_w": float(bmae[1]),
        "mean_command": [float(x) for x in np.asarray(windows.mean_command)],
        "mpc_loss": loss_sum / count,
        "rollout_image_l1": img_sum / count,
        "ratio_to_baseline": _ratio(float(mse.sum()), float(bmse.sum())),
        "beats_baseline": bool(mse.sum() < bmse.sum()),
    }


def format_report(report: dict[str, Any]) -> str:
    if report.get("model") == "viewnet":
        return (
            f"ViewNet on {report['held_out_pairs']} held-out pairs: L1 {report['viewnet_l1']:.5f} "
            f"(reversed {report['viewnet_l1_reversed']:.5f}) vs copy-the-input baseline "
            f"{report['copy_baseline_l1']:.5f} -> ratio {report['ratio_to_baseline']:.3f}"
            f"{'' if report['beats_baseline'] else '  (DOES NOT BEAT THE BASELINE)'}"
        )
    if report.get("model") == "velocitynet":
        return (
            f"VelocityNet on {report['held_out_windows']} held-out windows: first-command MSE "
            f"{report['mse_first_command']:.5f} (MAE v {report['mae_v']:.4f} m/s, w {report['mae_w']:.4f} rad/s)"
            f" vs mean-command baseline MSE {report['mean_baseline_mse']:.5f} (MAE v "
            f"{report['mean_baseline_mae_v']:.4f}, w {report['mean_baseline_mae_w']:.4f}) -> ratio "
            f"{report['ratio_to_baseline']:.3f}{'' if report['beats_baseline'] else '  (DOES NOT BEAT THE BASELINE)'}"
        )
    return str(report)


def check_gain(report: dict[str, Any], where: str) -> None:
    """Raise NoGainError, one line naming the stage, its figure and the baseline, when ``report`` (a stage's
    report.json; ``where`` its folder) is above MAX_RATIO times its baseline."""
    go_on = f"stopping; the model stays in {where}, --allow-no-gain goes on with it"
    if report.get("model") == "viewnet":
        copy = report["copy_baseline_l1"]
        fwd, rev = _ratio(report["viewnet_l1"], copy), _ratio(report["viewnet_l1_reversed"], copy)
        if not max(fwd, rev) <= MAX_RATIO:
            raise NoGainError(
                f"ViewNet did not learn: held-out L1 {report['viewnet_l1']:.5f} (reversed "
                f"{report['viewnet_l1_reversed']:.5f}) is {fwd:.3f}x ({rev:.3f}x) the copy-the-input baseline "
                f"{copy:.5f}, above {MAX_RATIO}x; {go_on}"
            )
    elif report.get("model") == "velocitynet":
        ratio = _ratio(report["mse_first_command"], report["mean_baseline_mse"])
        if not ratio <= MAX_RATIO:
            raise NoGainError(
                f"VelocityNet did not learn: held-out first-command MSE {report['mse_first_command']:.5f} is "
                f"{ratio:.3f}x the mean-command baseline {report['mean_baseline_mse']:.5f}, above "
                f"{MAX_RATIO}x; {go_on}"
            )
    else:
        raise ValueError(f"{where}: not a stage report (model {report.get('model')!r})")
