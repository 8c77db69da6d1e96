"""Rays against the house's surfaces: the one intersection routine the camera and the rangefinder share.

A surface is a segment a -> b (``House.segments``) seen from its front side only: walls face the rooms,
furniture faces outwards, so from free space the nearest hit of a ray is always on a front face. With
ap = a - origin, e = b - a and cross(p, q) = p_x q_y - p_y q_x, a ray origin + t * dir meets the segment's
line at t = cross(ap, e) / cross(dir, e), at s = cross(ap, dir) / cross(dir, e) along it; the origin sees
the front face where cross(ap, e) < 0. :func:`inverse_depths` returns 1/t for every (ray, front face)
pair from one float32 matrix product, so the caller takes a maximum instead of dividing per pair.
"""

from __future__ import annotations

import numpy as np


class Surfaces:
    """Segments ready for ray casting: start points and the perpendiculars of their directions."""

    def __init__(self, a: np.ndarray, b: np.ndarray) -> None:
        self.a = np.asarray(a, dtype=np.float64)
        e = np.asarray(b, dtype=np.float64) - self.a
        # cross(p, e) = p @ e_perp with e_perp = (e_y, -e_x)
        self.e_perp_t = np.stack([e[:, 1], -e[:, 0]])  # (2, S)
        self.e_perp = np.ascontiguousarray(self.e_perp_t.T)  # (S, 2)

    def __len__(self) -> int:
        return len(self.a)

    def from_origin(self, x: float, y: float) -> tuple[np.ndarray, np.ndarray]:
        """(ap, t_num): start points relative to the origin (S, 2), and cross(ap, e) (S,), < 0 on a
        front face."""
        ap = self.a - (x, y)
        return ap, np.einsum("ij,ij->i", ap, self.e_perp)


def inverse_depths(
    dirs: np.ndarray, e_perp_t: np.ndarray, ap: np.ndarray, t_num: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """1/t of each ray (dirs (N, 2), world frame) on each front face (columns of e_perp_t (2, n), rows of
    ap (n, 2), t_num (n,) < 0), as (N, n) float32: > 0 where the ray hits the face within the segment,
    <= 0 elsewhere. Also returns cross(ap, dir) and cross(dir, e), whose ratio is the position s along it.
    With unit directions 1/t is 1 / range; with a forward component of 1 it is 1 / forward depth."""
    n = len(t_num)
    m = np.empty((2, 2 * n), np.float32)  # float32 halves the work per ray and segment pair
    m[:, :n] = e_perp_t
    m[0, n:] = -ap[:, 1]
    m[1, n:] = ap[:, 0]
    r = dirs @ m  # (N, 2n): [denom | s_num], cross(dir, e) and cross(ap, dir)
    denom = r[:, :n]
    s_num = r[:, n:]
    # A front face is hit iff the ray points at it (denom < 0) within the segment (0 <= s <= 1); then
    # t = t_num / denom > 0. Where denom >= 0, 1/t = denom / t_num is <= 0 and loses to any real hit, so
    # that test is folded into the range test below.
    inv_t = denom * (1.0 / t_num).astype(np.float32)
    inv_t *= (s_num <= 0) & (s_num >= denom)
    return inv_t, s_num, denom
