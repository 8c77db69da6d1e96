"""A gymnasium.Env over the in-process Simulator.

Action: Box([-1, 1]^2) scaled to (v, w) = (a0 * v_max, a1 * w_max), applied for `control_dt` seconds.
Observation: the camera image, Box(0, 255, (H, W, 3), uint8). The reward is the forward progress
(metres moved along the heading) minus a penalty when the step touched an obstacle; it is only a placeholder,
the project trains offline from recorded data. Episodes truncate after `max_steps`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from vtr.runtime.contracts import CONTROL_DT
from vtr.sim2d.config import SimConfig
from vtr.sim2d.simulator import Simulator


@dataclass(frozen=True)
class GymEnvConfig:
    """The gymnasium adapter."""

    sim: SimConfig = field(default_factory=SimConfig)
    """The simulator underneath."""
    control_dt: float = CONTROL_DT
    """Seconds of simulated time per env step (the paper's control step)."""
    max_steps: int = 500
    """Steps before the episode is truncated."""
    collision_penalty: float = 0.1
    """Reward subtracted on a step that touched an obstacle."""
    random_start: bool = True
    """Start each episode at one of the house's start poses drawn by the reset seed (else the first)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.control_dt) and 0 < self.control_dt <= 5.0):
            raise ValueError(f"GymEnvConfig.control_dt must be in (0, 5] s, got {self.control_dt!r}")
        if not isinstance(self.max_steps, int) or self.max_steps < 1:
            raise ValueError(f"GymEnvConfig.max_steps must be an integer >= 1, got {self.max_steps!r}")
        if not (math.isfinite(self.collision_penalty) and self.collision_penalty >= 0):
            raise ValueError(f"GymEnvConfig.collision_penalty must be >= 0, got {self.collision_penalty!r}")


class SimEnv(gym.Env):
    """Gymnasium environment wrapping sim2d.Simulator."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, cfg: GymEnvConfig | None = None, render_mode: str | None = None) -> None:
        self.cfg = cfg if cfg is not None else GymEnvConfig()
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode = render_mode
        self.sim = Simulator(self.cfg.sim)
        cam = self.cfg.sim.camera
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.observation_space = gym.spaces.Box(0, 255, shape=(cam.height, cam.width, 3), dtype=np.uint8)
        self._steps = 0
        self._last: np.ndarray | None = None

    def _info(self) -> dict[str, Any]:
        p = self.sim.pose
        return {"pose": (p.x, p.y, p.yaw), "time": self.sim.time, "collided": self.sim.collided}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        starts = self.sim.house.start_poses
        pose = starts[int(self.np_random.integers(len(starts)))] if self.cfg.random_start else starts[0]
        if options and "pose" in options:
            pose = options["pose"]
        sim_seed = int(self.np_random.integers(2**31 - 1))
        self._last = self.sim.reset(pose=pose, seed=sim_seed)
        self._steps = 0
        return self._last, self._info()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(2), -1.0, 1.0)
        before = self.sim.pose
        self._last = self.sim.step(a[0] * self.cfg.sim.v_max, a[1] * self.cfg.sim.w_max, self.cfg.control_dt)
        after = self.sim.pose
        progress = (after.x - before.x) * math.cos(before.yaw) + (after.y - before.y) * math.sin(before.yaw)
        reward = float(progress - (self.cfg.collision_penalty if self.sim.collided else 0.0))
        self._steps += 1
        truncated = self._steps >= self.cfg.max_steps
        return self._last, reward, False, truncated, self._info()

    def render(self) -> np.ndarray | None:
        if self.render_mode == "rgb_array":
            return self._last if self._last is not None else self.sim.observe()
        return None
