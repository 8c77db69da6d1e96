"""The online-MPC baseline: ViewNet rolled forward at every step to search (v, w) (the paper's future work)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np


class ViewNetMPC:
    """Online MPC: at every step, search (v, w) sequences by rolling ViewNet forward (cross-entropy method).

    Candidates are N-step sequences of (v, w) inside the limits; each is rolled through ViewNet from the
    current image and scored by the mean absolute difference of every predicted image to the subgoal (the
    last one weighted double). The best sequence is returned as a (2, N) array like VelocityNet's output.
    """

    def __init__(
        self, checkpoint: Path, horizon: int, samples: int, iterations: int, threads: int, seed: int
    ):
        import torch

        from vtr.training.checkpoint import load_model

        torch.set_num_threads(threads)
        kind, self.net, _ = load_model(checkpoint)
        if kind != "viewnet":
            raise ValueError(f"{checkpoint} holds a {kind}, not a viewnet")
        self.torch = torch
        self.image_shape = (int(self.net.cfg.image_size), int(self.net.cfg.image_size))
        self.horizon, self.samples, self.iterations = horizon, samples, iterations
        self.v_max, self.w_max = float(self.net.cfg.v_max), float(self.net.cfg.w_max)
        self.rng = np.random.default_rng(seed)
        self._mean = np.zeros((horizon, 2))

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        from vtr.runtime.preprocess import to_nchw

        torch = self.torch
        limits = np.array([self.v_max, self.w_max])
        cur = torch.from_numpy(to_nchw(np.asarray(current)))  # (1, 3, H, W); a frame from the repeat loop
        goal = torch.from_numpy(to_nchw(np.asarray(subgoal)))
        mean, std = np.vstack([self._mean[1:], np.zeros((1, 2))]), limits * 0.5  # warm start: shifted plan
        best, best_cost = np.zeros((self.horizon, 2)), math.inf
        for _ in range(self.iterations):
            cand = self.rng.normal(mean, std, size=(self.samples, self.horizon, 2))
            cand[0] = mean
            cand[1] = 0.0
            cand = np.clip(cand, -limits, limits)
            costs = self._costs(cur, goal, cand)
            order = np.argsort(costs)
            if costs[order[0]] < best_cost:
                best, best_cost = cand[order[0]], float(costs[order[0]])
            elite = cand[order[: max(2, self.samples // 8)]]
            mean, std = elite.mean(axis=0), elite.std(axis=0) + 0.02 * limits
        self._mean = best
        return best.T.astype(np.float32)  # (2, N)

    def _costs(self, cur: Any, goal: Any, cand: np.ndarray) -> np.ndarray:
        torch = self.torch
        k = cand.shape[0]
        vel = torch.from_numpy(cand.astype(np.float32))  # (K, N, 2)
        with torch.inference_mode():
            img = cur.expand(k, -1, -1, -1)  # (K, 3, H, W)
            cost = torch.zeros(k)
            for j in range(self.horizon):
                img = self.net(img, vel[:, j])  # (K, 3, H, W)
                weight = 2.0 if j == self.horizon - 1 else 1.0
                cost += weight * (img - goal).abs().mean(dim=(1, 2, 3))
        return cost.numpy()
