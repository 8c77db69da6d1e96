"""Teach and repeat in a house whose floor changed in between: frames of the same poses in another appearance.

A policy trained only on (current, subgoal) pairs from one drive always sees the same floor in both images, so
it may steer by the floor's pattern; when the floor is re-laid between teach and repeat it steers away (issue
20: `floor_recoloured`). Collection (`vtr collect --houses ... --appearances K`) therefore renders every frame a
second time, from the same pose, in one of K versions of the house whose floor is laid again
(sim2d.surfaces.redrawn_floor; some also with every wall re-finished), one version per episode. Training
(`--appearance-swap P`) takes, for a share P of the MPC loss's windows, either the subgoal images or the
current-side frames from that other appearance: the commands between the poses are the same, so the labels and
the ViewNet targets stay exact (the image targets always share the current image's appearance).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import torch

#: Share of the appearance versions whose walls are re-finished too (the floor is always laid again).
WALLS_TOO = 0.3


def appearance_cameras(house: str, camera_cfg: Any, count: int, seed: int) -> list[Any]:
    """``count`` cameras of ``house`` with its floor laid again (seeded by ``seed``), same camera settings."""
    from vtr.sim2d.appearance import apply_changes
    from vtr.sim2d.camera import Camera
    from vtr.sim2d.house import House, house_data
    from vtr.sim2d.surfaces import redrawn_floor

    data, source = house_data(house)
    out = []
    for k in range(count):
        rng = np.random.default_rng([seed, k, 29])
        alt = copy.deepcopy(data)
        alt["floor"] = redrawn_floor(data["floor"], rng)
        if rng.random() < WALLS_TOO:
            alt = apply_changes(alt, [f"retexture:walls={int(rng.integers(1, 2**31 - 1))}"])
        out.append(Camera(House(alt, f"{source} (floor laid again, version {k})"), camera_cfg))
    return out


def render_appearances(
    cameras: list[Any],
    poses: np.ndarray,
    episodes: np.ndarray,
    out: np.ndarray,
    seed: int,
    on_frame: Any = None,
) -> None:
    """Fill ``out`` (T, H, W, 3) with the frames at ``poses`` (T, 3), each episode in one of ``cameras``."""
    rng = np.random.default_rng([seed, 31])
    pick: dict[int, int] = {}
    for t, (x, y, yaw) in enumerate(np.asarray(poses, dtype=np.float64)):
        ep = int(episodes[t])
        if ep not in pick:
            pick[ep] = int(rng.integers(len(cameras)))
        out[t] = cameras[pick[ep]].render(float(x), float(y), float(yaw))
        if on_frame is not None:
            on_frame()


def swap_appearance(
    frames: torch.Tensor, other: torch.Tensor, probability: float, gen: torch.Generator
) -> tuple[torch.Tensor, torch.Tensor]:
    """(current-side frames, subgoal frames), each (B, L, 3, H, W), for the MPC loss.

    ``frames`` and ``other`` are the same windows in two appearances. A window is swapped with ``probability``:
    half of the swapped ones take their subgoals from ``other`` (a repeat in the changed house, as taught
    before), the other half their current-side frames and ViewNet targets (a repeat in the taught house of
    a route taught after the change). The rest use ``frames`` for both."""
    b = frames.shape[0]
    u = torch.rand(b, generator=gen).to(frames.device)
    goal_other = (u < probability / 2).view(b, 1, 1, 1, 1)
    current_other = ((u >= probability / 2) & (u < probability)).view(b, 1, 1, 1, 1)
    return torch.where(current_other, other, frames), torch.where(goal_other, other, frames)
