"""The simulator: a house, a differential-drive robot, its camera and range scanner (numpy + pymunk only).

A functional core, `sim_step(state, v, w, duration, rng, cfg) -> state`, advances physics (the pymunk
world inside the state is updated in place: pymunk spaces cannot be copied cheaply); `Simulator` keeps
the state and renders. The random generator for actuation noise is created by reset(seed), so the
same seed and the same commands give the same images, bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from vtr.runtime.scan import Scan
from vtr.sim2d.camera import Camera
from vtr.sim2d.config import Pose, SimConfig
from vtr.sim2d.house import House, load_house
from vtr.sim2d.moving import moved_camera, moved_house
from vtr.sim2d.physics import World, advance, build_world, pose_of
from vtr.sim2d.rangefinder import Rangefinder
from vtr.sim2d.sensor import Sensor, describe


@dataclass
class SimState:
    """Everything that changes while the simulation runs."""

    world: World
    time: float
    collided: bool
    bias: tuple[float, float, float] = (1.0, 1.0, 0.0)  # (v scale, w scale, curvature rad/m), see draw_bias


#: Curvature drift per unit of noise (rad per metre driven): unequal wheel radii make a robot told to
#: drive straight curve; at noise 0.05 about 0.025 rad/m, so 2 m of open-loop driving end ~5 cm aside.
CURVATURE_PER_NOISE = 0.5


def draw_bias(cfg: SimConfig, seed: int) -> tuple[float, float, float]:
    """The systematic part of the actuation noise, drawn once per reset(seed): a real robot's odometry
    error is mostly a calibration error (wheel radius, track width) that does not average out, which is
    what makes open-loop replay drift and what the camera has to correct."""
    if cfg.noise == 0.0:
        return (1.0, 1.0, 0.0)
    b = np.random.default_rng([seed, 1]).standard_normal(3)
    return (1.0 + cfg.noise * b[0], 1.0 + cfg.noise * b[1], CURVATURE_PER_NOISE * cfg.noise * b[2])


def noisy_command(
    v: float,
    w: float,
    cfg: SimConfig,
    rng: np.random.Generator,
    bias: tuple[float, float, float] = (1.0, 1.0, 0.0),
) -> tuple[float, float]:
    """Actuation noise model (see SimConfig.noise): the episode's systematic `bias`, then per-step
    jitter. Draws 4 normals per call whatever the command is, so the random stream stays aligned
    between runs that differ only in their commands."""
    e = rng.standard_normal(4)
    if cfg.noise == 0.0:
        return v, w
    v_scale, w_scale, curvature = bias
    v, w = v * v_scale, w * w_scale + curvature * v
    vn = v * (1.0 + cfg.noise * e[0]) + (0.1 * cfg.noise * cfg.v_max * e[1] if v != 0.0 else 0.0)
    wn = w * (1.0 + cfg.noise * e[2]) + (0.1 * cfg.noise * cfg.w_max * e[3] if w != 0.0 else 0.0)
    return vn, wn


def clamp_command(v: float, w: float, cfg: SimConfig) -> tuple[float, float]:
    """Clamp a Twist to the robot's limits; non-finite values are rejected."""
    if not (math.isfinite(v) and math.isfinite(w)):
        raise ValueError(f"velocity command must be finite, got v={v!r}, w={w!r}")
    return min(max(float(v), -cfg.v_max), cfg.v_max), min(max(float(w), -cfg.w_max), cfg.w_max)


def sim_step(
    state: SimState, v: float, w: float, duration: float, rng: np.random.Generator, cfg: SimConfig
) -> SimState:
    """Apply the clamped, noisy command for `duration` seconds of simulated time."""
    v, w = clamp_command(v, w, cfg)
    v, w = noisy_command(v, w, cfg, rng, state.bias)
    touched = advance(state.world, v, w, duration, cfg.physics_dt)
    return SimState(state.world, state.time + duration, touched, state.bias)


class Simulator:
    """In-process simulator; see docs/ARCHITECTURE.md for the contract."""

    def __init__(self, cfg: SimConfig | None = None) -> None:
        self.cfg = cfg if cfg is not None else SimConfig()
        self.house: House = load_house(self.cfg.house, self.cfg.changes)
        self.camera = Camera(self.house, self.cfg.camera)
        sensor = self.cfg.sensor
        self._sensor = (
            Sensor(sensor, self.cfg.camera.focal_px) if sensor is not None and sensor.active else None
        )
        self._command = (0.0, 0.0)  # the last commanded (v, w): the motion the sensor blurs
        self._rangefinder: Rangefinder | None = None
        self._rng = np.random.default_rng(0)
        self._state: SimState | None = None
        self.reset()

    # ------------------------------------------------------------------------------------------ control
    def reset(self, pose: Pose | None = None, seed: int | None = None) -> np.ndarray:
        """Rebuild the world with the robot at `pose` (default: the house's first start pose); returns the image.

        `seed` seeds the actuation noise; None means seed 0, so runs are reproducible unless asked otherwise.
        """
        if pose is None:
            pose = self.house.start_poses[0]
        pose = Pose(float(pose[0]), float(pose[1]), float(pose[2]))
        if not all(math.isfinite(c) for c in pose):
            raise ValueError(f"reset pose must be finite, got {pose!r}")
        if not self.house.is_free(pose.x, pose.y, self.cfg.robot_radius):
            raise ValueError(
                f"reset pose ({pose.x:.3f}, {pose.y:.3f}) is not free space for a robot of radius "
                f"{self.cfg.robot_radius} m"
            )
        seed = 0 if seed is None else seed
        self._rng = np.random.default_rng(seed)
        world = build_world(self.house, pose, self.cfg.robot_radius)
        self._state = SimState(world, 0.0, False, draw_bias(self.cfg, seed))
        self._command = (0.0, 0.0)
        if self._sensor is not None:
            self._sensor.reset(seed)
        return self.observe()

    def set_house(self, house: str) -> None:
        """Swap the house under the robot (a map name, a house JSON path or ``random:SEED``), keeping its
        pose, clock and actuation noise: the world changing mid-run (an evaluation takes an obstacle away).
        The robot's pose must be free space in the new house."""
        state = self._require()
        pose = self.pose
        new = load_house(house, self.cfg.changes)
        if not new.is_free(pose.x, pose.y, self.cfg.robot_radius):
            raise ValueError(f"the robot's pose ({pose.x:.3f}, {pose.y:.3f}) is not free space in {house}")
        self.cfg = replace(self.cfg, house=str(house))
        self.house, self.camera = new, Camera(new, self.cfg.camera)
        world = build_world(new, pose, self.cfg.robot_radius)
        self._state = SimState(world, state.time, False, state.bias)
        self._rangefinder = None  # the scan sees the new house too

    def move_furniture(self, name: str, center: tuple[float, float]) -> None:
        """Move the furniture piece ``name`` so that its centre is at ``center``, mid-run (the robot's pose,
        clock and actuation noise kept; camera, scan and physics see it at once): something that moves
        through the house (the evaluation's moving obstacle). Raises ValueError, moving nothing, where the
        piece would overlap the robot."""
        state = self._require()
        pose = self.pose
        new = moved_house(self.house, name, center)
        if not new.is_free(pose.x, pose.y, self.cfg.robot_radius):
            raise ValueError(f"{name} at ({center[0]:.3f}, {center[1]:.3f}) would overlap the robot")
        self.house, self.camera, self._rangefinder = new, moved_camera(self.camera, new), None
        world = build_world(new, pose, self.cfg.robot_radius)
        self._state = SimState(world, state.time, state.collided, state.bias)

    def step(self, v: float, w: float, duration: float) -> np.ndarray:
        """Drive with (v, w), clamped to the limits, for `duration` s of simulated time; returns the image."""
        self.advance(v, w, duration)
        return self.observe()

    def advance(self, v: float, w: float, duration: float) -> None:
        """Like step() without rendering (for callers that need many poses and few images)."""
        if not (isinstance(duration, (int, float)) and math.isfinite(duration)) or not (
            0.0 <= duration <= self.cfg.max_step_duration
        ):
            raise ValueError(
                f"step duration must be in [0, {self.cfg.max_step_duration}] s, got {duration!r}"
            )
        self._state = sim_step(self._require(), v, w, float(duration), self._rng, self.cfg)
        self._command = clamp_command(v, w, self.cfg)

    def observe(self) -> np.ndarray:
        """The camera image at the current pose (no time advance)."""
        p = self.pose
        image = self.camera.render(p.x, p.y, p.yaw)
        if self._sensor is not None:
            image = self._sensor.apply(image, *self._command, self.time)
        return image

    @property
    def rangefinder(self) -> Rangefinder:
        """The range scanner of ``cfg.rangefinder``, built on first use."""
        if self._rangefinder is None:
            self._rangefinder = Rangefinder(self.house, self.cfg.rangefinder)
        return self._rangefinder

    def scan(self) -> Scan:
        """The range scan at the current pose (no time advance); see sim2d.rangefinder."""
        p = self.pose
        return self.rangefinder.scan(p.x, p.y, p.yaw)

    # ------------------------------------------------------------------------------------------ state
    def _require(self) -> SimState:
        if self._state is None:
            raise RuntimeError("Simulator.reset() has not been called")
        return self._state

    @property
    def pose(self) -> Pose:
        return pose_of(self._require().world)

    @property
    def time(self) -> float:
        return self._require().time

    @property
    def collided(self) -> bool:
        return self._require().collided

    def info(self) -> dict:
        """Static and current facts for clients (the server's hello)."""
        c = self.cfg.camera
        return {
            "map": self.house.name,
            "map_source": str(self.house.source),
            "changes": list(self.cfg.changes),
            "rooms": [r.name for r in self.house.rooms],
            "camera": {
                "width": c.width,
                "height": c.height,
                "fov_deg": c.fov_deg,
                "camera_height": c.camera_height,
                "wall_height": c.wall_height,
                "brightness": c.brightness,
                "supersample": c.supersample,
                "max_range": c.max_range,
                "encoding": "rgb8",
            },
            "limits": {"v_max": self.cfg.v_max, "w_max": self.cfg.w_max},
            "robot_radius": self.cfg.robot_radius,
            "physics_dt": self.cfg.physics_dt,
            "noise": self.cfg.noise,
            **({"sensor": describe(self.cfg.sensor)} if self.cfg.sensor is not None else {}),
            "time": self.time,
        }
