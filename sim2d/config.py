"""Configuration dataclasses and the pose type of the simulator (no heavy imports)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from vtr.runtime.contracts import CAMERA, ROBOT_RADIUS, V_MAX, W_MAX, Pose
from vtr.runtime.scan import MAX_BEAMS, MAX_SCAN_RANGE
from vtr.sim2d.sensor import SensorConfig

__all__ = ["V_MAX", "W_MAX", "CameraConfig", "Pose", "RangefinderConfig", "SimConfig", "camera_config"]


def _finite_positive(name: str, value: float) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True)
class CameraConfig:
    """Forward-looking pinhole camera rendered by raycasting the 2D house."""

    width: int = CAMERA.width
    """Image width in pixels (the paper's network input is 128)."""
    height: int = CAMERA.height
    """Image height in pixels."""
    fov_deg: float = CAMERA.fov_deg
    """Horizontal field of view in degrees; square pixels, so the vertical fov follows from the aspect ratio."""
    camera_height: float = CAMERA.height_m
    """Height of the optical centre above the floor (m), below wall_height; furniture lower than the camera is
    seen from above (its top, sim2d.camera_tops)."""
    wall_height: float = 2.5
    """Height of the walls (m); the ceiling is drawn above it."""
    brightness: float = 1.0
    """Multiplier on every pixel before clipping to 0..255 (robustness tests: 0.5 darker, 1.5 brighter)."""
    supersample: int = 1
    """Render at supersample x the resolution and average down. 1 by default: textures are already
    anti-aliased by mip levels (per row on the floor, per column on surfaces), so 2 (four times the cost)
    only smooths silhouette edges, not worth halving the simulator's throughput for training data."""
    max_range: float = 20.0
    """Rays that hit nothing within this distance (m) show the far colour."""
    shading_distance: float = 6.0
    """Distance (m) over which surfaces fade towards ambient light (distance shading)."""
    ambient: float = 0.35
    """Fraction of the light that remains at infinite distance (0..1)."""

    def __post_init__(self) -> None:
        for name in ("width", "height", "supersample"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"CameraConfig.{name} must be an integer >= 1, got {value!r}")
        if self.width * self.supersample > 4096 or self.height * self.supersample > 4096:
            raise ValueError(
                f"CameraConfig: rendered size {self.width}x{self.height} x{self.supersample} is too large"
            )
        if not (isinstance(self.fov_deg, (int, float)) and 1.0 <= self.fov_deg <= 170.0):
            raise ValueError(f"CameraConfig.fov_deg must be in [1, 170], got {self.fov_deg!r}")
        for name in ("camera_height", "wall_height", "brightness", "max_range", "shading_distance"):
            _finite_positive(f"CameraConfig.{name}", getattr(self, name))
        if self.camera_height >= self.wall_height:
            raise ValueError(
                f"CameraConfig.camera_height ({self.camera_height}) must be below wall_height ({self.wall_height})"
            )
        if not (isinstance(self.ambient, (int, float)) and 0.0 <= self.ambient <= 1.0):
            raise ValueError(f"CameraConfig.ambient must be in [0, 1], got {self.ambient!r}")

    @property
    def focal_px(self) -> float:
        """Focal length in (output) pixels."""
        return 0.5 * self.width / math.tan(math.radians(self.fov_deg) / 2.0)


def camera_config(width: int, height: int, camera: tuple[float, float] | None = None) -> CameraConfig:
    """A width x height CameraConfig; ``camera``: (horizontal field of view in degrees, height above the floor
    in m), None for the default camera (the shipped model's)."""
    if camera is None:
        return CameraConfig(width=width, height=height)
    fov, h = camera
    return CameraConfig(width=width, height=height, fov_deg=float(fov), camera_height=float(h))


@dataclass(frozen=True)
class RangefinderConfig:
    """A planar range scanner (a 2D lidar) on the robot's centreline, below every furniture top: it sees
    walls, furniture and obstacles (sim2d.rangefinder)."""

    beams: int = 181
    """Number of beams, spread evenly over the field of view (1.5 deg apart by default)."""
    fov_deg: float = 270.0
    """Field of view in degrees, centred straight ahead; 360 gives a full turn without a repeated beam."""
    range_max: float = 5.0
    """Farther than this (m) counts as nothing seen."""
    x_m: float = 0.1
    """Mounting: metres forward of the robot's centre (inside its footprint)."""

    def __post_init__(self) -> None:
        if (
            not isinstance(self.beams, int)
            or isinstance(self.beams, bool)
            or not 1 <= self.beams <= MAX_BEAMS
        ):
            raise ValueError(
                f"RangefinderConfig.beams must be an integer in 1..{MAX_BEAMS}, got {self.beams!r}"
            )
        if not (isinstance(self.fov_deg, (int, float)) and 0.0 < self.fov_deg <= 360.0):
            raise ValueError(f"RangefinderConfig.fov_deg must be in (0, 360], got {self.fov_deg!r}")
        _finite_positive("RangefinderConfig.range_max", self.range_max)
        if self.range_max > MAX_SCAN_RANGE:
            raise ValueError(
                f"RangefinderConfig.range_max must be <= {MAX_SCAN_RANGE:g} m, got {self.range_max!r}"
            )
        if not (isinstance(self.x_m, (int, float)) and math.isfinite(self.x_m)):
            raise ValueError(f"RangefinderConfig.x_m must be a finite number, got {self.x_m!r}")


@dataclass(frozen=True)
class SimConfig:
    """The simulator: house, robot, physics and actuation noise."""

    house: str = "house"
    """Map name in sim2d/maps (without .json), a path to a house JSON file, or ``random:SEED`` for a
    procedural house (sim2d.procedural)."""
    changes: tuple[str, ...] = ()
    """Appearance changes applied to the house (sim2d.appearance), e.g. ("retexture:wall=3",
    "light:level=0.6"): the same house looking different between teach and repeat."""
    camera: CameraConfig = field(default_factory=CameraConfig)
    """Camera parameters."""
    robot_radius: float = ROBOT_RADIUS
    """Radius of the circular differential-drive robot (m)."""
    rangefinder: RangefinderConfig = field(default_factory=RangefinderConfig)
    """The range scanner ``Simulator.scan`` reads (built on first use: a camera-only run pays nothing)."""
    physics_dt: float = 0.02
    """Physics substep (s); a step of `duration` runs ceil(duration / physics_dt) equal substeps. At 0.5 m/s
    a substep moves 1 cm, far less than the robot radius and the wall thickness, so nothing tunnels."""
    noise: float = 0.0
    """Actuation noise level, 0 = off. Two parts, both seeded by reset(seed):
    systematic (drawn once per reset, like a miscalibrated robot): v <- v * (1 + noise * b1),
    w <- w * (1 + noise * b2) + 0.5 * noise * b3 * v (a curving drift, rad per metre driven);
    then per step: v' = v * (1 + noise * e1) + 0.1 * noise * V_MAX * e2 and
    w' = w * (1 + noise * e3) + 0.1 * noise * W_MAX * e4, held for the whole step,
    with b_i, e_i ~ N(0, 1). The additive jitter only applies to a non-zero command (a stopped motor does
    not creep). So noise=0.05 means a 5% speed-scale error, a 0.025 rad/m curvature drift, 5% per-step
    speed error, and 0.0025 m/s, 0.005 rad/s jitter (1 sigma each)."""
    v_max: float = V_MAX
    """Clamp on |v| (m/s); commands beyond it are clamped, not rejected."""
    w_max: float = W_MAX
    """Clamp on |w| (rad/s)."""
    max_step_duration: float = 10.0
    """Longest duration accepted by one step() (s), a guard against a typo running for hours."""
    sensor: SensorConfig | None = None
    """Camera sensor realism applied to every frame (sim2d.sensor: motion blur from the commanded motion,
    lens distortion, exposure and white-balance drift and flicker, noise, JPEG); None: the ideal image."""

    def __post_init__(self) -> None:
        if not isinstance(self.house, str) or not self.house:
            raise ValueError(f"SimConfig.house must be a non-empty string, got {self.house!r}")
        if self.changes:
            from vtr.sim2d.appearance import parse_change  # numpy only; skipped when there is no change

            object.__setattr__(self, "changes", tuple(str(parse_change(c)) for c in self.changes))
        if not isinstance(self.camera, CameraConfig):
            raise ValueError(f"SimConfig.camera must be a CameraConfig, got {type(self.camera).__name__}")
        for name in ("robot_radius", "physics_dt", "v_max", "w_max", "max_step_duration"):
            _finite_positive(f"SimConfig.{name}", getattr(self, name))
        if not 0.05 <= self.robot_radius <= 0.5:
            raise ValueError(f"SimConfig.robot_radius must be in [0.05, 0.5] m, got {self.robot_radius!r}")
        if self.sensor is not None and not isinstance(self.sensor, SensorConfig):
            raise ValueError(
                f"SimConfig.sensor must be a SensorConfig or None, got {type(self.sensor).__name__}"
            )
        if not isinstance(self.rangefinder, RangefinderConfig):
            raise ValueError(f"SimConfig.rangefinder must be a RangefinderConfig, got {self.rangefinder!r}")
        if abs(self.rangefinder.x_m) >= self.robot_radius:
            raise ValueError(
                f"RangefinderConfig.x_m ({self.rangefinder.x_m} m) must lie inside the robot "
                f"(|x_m| < robot_radius = {self.robot_radius} m)"
            )
        if self.physics_dt > 0.05:
            raise ValueError(f"SimConfig.physics_dt must be <= 0.05 s (collisions), got {self.physics_dt!r}")
        if not (
            isinstance(self.noise, (int, float)) and math.isfinite(self.noise) and 0.0 <= self.noise <= 1.0
        ):
            raise ValueError(f"SimConfig.noise must be in [0, 1], got {self.noise!r}")
