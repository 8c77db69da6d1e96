"""A planar range scanner (a 2D lidar) cast against the house with the camera's ray routine (sim2d.rays).

The scanner sits ``x_m`` ahead of the robot's centre, level, below every furniture top, so each beam
meets the nearest wall, piece of furniture or obstacle (``--change obstacle:...`` boxes are furniture)
in the floor plan. A circle is seen as the polygon the camera draws, which encloses the physical disc.
The reading is a ``runtime.scan.Scan``: metres, +inf where nothing lies within ``range_max``; beams
follow REP-103 (0 straight ahead, counter-clockwise positive), like a ``sensor_msgs/LaserScan``.
"""

from __future__ import annotations

import math

import numpy as np

from vtr.runtime.scan import Scan, ScanSpec
from vtr.sim2d.config import RangefinderConfig
from vtr.sim2d.house import House
from vtr.sim2d.rays import Surfaces, inverse_depths


def scan_spec(cfg: RangefinderConfig) -> ScanSpec:
    """The beams of ``cfg`` as the protocol announces them: spread evenly over the field of view, centred
    straight ahead; a full turn (360 deg) has no beam twice."""
    fov = math.radians(cfg.fov_deg)
    if cfg.beams == 1:
        return ScanSpec(1, 0.0, fov, float(cfg.range_max), float(cfg.x_m))
    full_turn = cfg.fov_deg == 360.0
    increment = fov / (cfg.beams if full_turn else cfg.beams - 1)
    angle_min = -math.pi if full_turn else -fov / 2
    return ScanSpec(cfg.beams, angle_min, increment, float(cfg.range_max), float(cfg.x_m))


class Rangefinder:
    """Scans of a House from planar robot poses."""

    def __init__(self, house: House, cfg: RangefinderConfig | None = None) -> None:
        self.cfg = cfg if cfg is not None else RangefinderConfig()
        self.spec = scan_spec(self.cfg)
        seg = house.segments
        self._surfaces = Surfaces(seg.a, seg.b)
        # faces farther than range_max from the scanner's line of sight are dropped before the product
        self._inv_len = 1.0 / np.maximum(np.hypot(*(seg.b - seg.a).T), 1e-12)
        angles = self.spec.angle_min + self.spec.angle_increment * np.arange(self.spec.beams)
        self._beams = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # (N, 2) robot frame

    def ranges(self, x: float, y: float, yaw: float) -> np.ndarray:
        """(beams,) float32 metres from the scanner of a robot at (x, y, yaw); +inf where nothing is hit."""
        c, s = math.cos(yaw), math.sin(yaw)
        ox, oy = x + self.cfg.x_m * c, y + self.cfg.x_m * s
        ap, t_num = self._surfaces.from_origin(ox, oy)
        # -t_num / |e| is the distance from the scanner to a front face's line: beyond range_max, never hit
        front = np.flatnonzero((t_num < 0) & (-t_num * self._inv_len <= self.cfg.range_max))
        out = np.full(self.spec.beams, np.inf, dtype=np.float32)
        if front.size == 0:
            return out
        dirs = (self._beams @ np.array([[c, s], [-s, c]])).astype(np.float32)  # (N, 2) world frame, unit
        inv_t, _, _ = inverse_depths(dirs, self._surfaces.e_perp_t[:, front], ap[front], t_num[front])
        best = inv_t.max(axis=1)  # 1 / range of the nearest hit
        hit = best >= np.float32(1.0 / self.cfg.range_max)
        out[hit] = 1.0 / best[hit]
        np.minimum(out, np.float32(self.cfg.range_max), out=out, where=hit)  # float32 rounding at the edge
        return out

    def scan(self, x: float, y: float, yaw: float) -> Scan:
        """The reading of a robot at (x, y, yaw) as the runtime receives it."""
        spec = self.spec
        return Scan(spec.angle_min, spec.angle_increment, spec.range_max, self.ranges(x, y, yaw), spec.x_m)
