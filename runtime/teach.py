"""`vtr teach`: drive a scripted route (ROUTE.json) and record its visual trajectory (a Route .npz).

The robot is reset to the script's start, then each segment is driven in control steps of ``dt``
(0.1 s, the repeat's step): a segment of duration D takes round(D / dt) steps. Subgoal spacing, chosen
by ``TeachConfig.spacing``:

- ``"steps"`` (default, ``every=2``): a subgoal every k-th control step. k = 2 matches how VelocityNet is
  trained: its N = 2 predicted commands take image I_i to I_{i+2}.
- ``"distance"``: a subgoal when the robot has moved ``min_distance`` metres or turned ``min_angle``
  radians since the last one (needs poses from the robot).
- ``"image"``: a subgoal when the mean abs pixel change from the last subgoal reaches
  ``min_image_change`` (0..255), which adapts spacing to how fast the view changes.

The start image is always subgoal 0 and the final image is always the last subgoal.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vtr.runtime.address import EXAMPLE, check_endpoint
from vtr.runtime.cliargs import add_config_arguments, config_from_args, opt
from vtr.runtime.contracts import CONTROL_DT
from vtr.runtime.hello import accept_hello
from vtr.runtime.preprocess import image_error
from vtr.runtime.protocol import jsonable
from vtr.runtime.robot import Observation, ResettableRobot, RobotError
from vtr.runtime.route import Route
from vtr.runtime.route_script import RouteScript
from vtr.runtime.safety import limit_twist
from vtr.runtime.scan import Scan
from vtr.runtime.setting_spec import REQUIRED
from vtr.runtime.settings import default
from vtr.runtime.settings_cli import add_arguments as add_settings
from vtr.runtime.settings_cli import resolve

SPACING_RULES = ("steps", "distance", "image")


@dataclass
class TeachConfig:
    """How a route is driven and how subgoals are spaced (rules in the module docstring)."""

    dt: float = opt(CONTROL_DT, "control step in seconds (the repeat applies each command as long)")
    spacing: str = opt("steps", "subgoal spacing rule", choices=SPACING_RULES)
    every: int = opt(2, "'steps': a subgoal every k control steps")
    min_distance: float = opt(0.05, "'distance': metres travelled between subgoals")
    min_angle: float = opt(0.1, "'distance': radians turned between subgoals")
    min_image_change: float = opt(20.0, "'image': mean abs pixel change (0..255) between subgoals")
    seed: int | None = opt(0, "simulator actuation-noise seed at reset")

    def __post_init__(self) -> None:
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {self.dt!r}")
        if self.spacing not in SPACING_RULES:
            raise ValueError(f"spacing must be one of {SPACING_RULES}, got {self.spacing!r}")
        if self.every < 1:
            raise ValueError(f"every must be >= 1, got {self.every}")
        if not (self.min_distance > 0 and self.min_angle > 0 and self.min_image_change > 0):
            raise ValueError(
                f"min_distance, min_angle and min_image_change must be > 0, got "
                f"{self.min_distance}, {self.min_angle}, {self.min_image_change}"
            )

    def rule(self) -> dict[str, Any]:
        """The spacing rule as stored in the route's metadata."""
        params = {
            "steps": {"every": self.every},
            "distance": {"min_distance": self.min_distance, "min_angle": self.min_angle},
            "image": {"min_image_change": self.min_image_change},
        }[self.spacing]
        return {"rule": self.spacing, "dt": self.dt, **params}

    def subgoal_due(self, since: int, obs: Observation, last_image: np.ndarray, last_pose: tuple) -> bool:
        """Whether ``obs``, ``since`` control steps after the last subgoal, is the next one by this rule
        (`vtr teach` on a robot and from a ROS bag decide alike)."""
        if self.spacing == "steps":
            return since >= self.every
        if self.spacing == "image":
            return image_error(obs.image, last_image) >= self.min_image_change
        if obs.pose is None:
            raise ValueError(
                "spacing='distance' needs poses, but the robot reports none; use 'steps' or 'image'"
            )
        dist = math.hypot(obs.pose[0] - last_pose[0], obs.pose[1] - last_pose[1])
        return dist >= self.min_distance or abs(_wrap(obs.pose[2] - last_pose[2])) >= self.min_angle


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def _robot_info(robot: Any, dt: float) -> dict[str, Any]:
    """Camera/map description from the robot, when it offers one (SimClient's hello, LocalRobot.sim.info).

    A protocol robot's hello is checked as `vtr repeat` checks it (``runtime.hello.accept_hello``): a broken
    hello is refused, an older one accepted with a warning naming what it should add."""
    if hasattr(robot, "handshake"):
        hello, warnings = accept_hello(robot.handshake(), dt)
        for warning in warnings:
            print(f"vtr teach: warning: {warning}", file=sys.stderr)
        info = dict(hello.info)
        # the hello schema (docs/PROTOCOL.md) puts camera and map at the top level; info is free-form
        info["camera"] = {k: v for k, v in dataclasses.asdict(hello.camera).items() if v is not None}
        if hello.map is not None:
            info["map"] = hello.map
        return info
    timeouts = getattr(robot, "timeouts", 0)
    try:
        if hasattr(robot, "hello"):
            header = robot.hello()
            info = dict(header.get("info") or {})
            info.update({k: header[k] for k in ("camera", "map") if header.get(k) is not None})
            return info
        sim = getattr(robot, "sim", None)
        if sim is not None and hasattr(sim, "info"):
            return dict(jsonable(sim.info()))
    except RobotError:
        if getattr(robot, "timeouts", 0) > timeouts:
            raise  # nothing answers: say so now, not after a second round of tries on reset
        return {}  # a bridge that does not implement hello
    except Exception:
        return {}
    return {}


def teach(robot: ResettableRobot, script: RouteScript, cfg: TeachConfig | None = None) -> Route:
    """Drive ``script`` on ``robot`` and return the recorded Route (not yet saved)."""
    cfg = cfg or TeachConfig()
    info = _robot_info(robot, cfg.dt)
    obs = robot.reset(pose=script.start, seed=cfg.seed)
    images: list[np.ndarray] = []
    poses: list[tuple[float, float, float]] = []
    commands: list[list[float]] = []
    scans: list[Scan | None] = []  # the range scan at each subgoal, when the robot has one
    pending = False  # the last subgoal still waits for the command that follows it

    def record(o: Observation) -> None:
        nonlocal pending
        images.append(np.array(o.image, dtype=np.uint8, copy=True))
        poses.append(o.pose if o.pose is not None else (math.nan, math.nan, math.nan))
        commands.append([0.0, 0.0])
        scans.append(o.scan)
        pending = True

    record(obs)
    since = 0
    for segment in script.segments:
        for _ in range(max(1, round(segment.duration / cfg.dt))):
            if pending:
                commands[-1] = [segment.v, segment.w]
                pending = False
            obs = robot.step(segment.v, segment.w, cfg.dt)
            since += 1
            if cfg.subgoal_due(since, obs, images[-1], poses[-1]):
                record(obs)
                since = 0
    robot.stop()
    if since > 0:
        record(obs)
    height, width = images[0].shape[:2]
    camera = (
        info.get("camera") if isinstance(info.get("camera"), dict) else {"height": height, "width": width}
    )
    return Route(
        images=np.stack(images),
        poses=np.array(poses, dtype=np.float64),
        commands=np.array(commands, dtype=np.float64),
        name=script.name,
        camera=camera,
        spacing=cfg.rule(),
        map=info.get("map") if isinstance(info.get("map"), str) else None,
        dt=cfg.dt,
        clearance=taught_clearance(scans, np.array(commands, dtype=np.float64)),
    )


def taught_clearance(scans: list[Scan | None], commands: np.ndarray) -> np.ndarray | None:
    """(L,) free distance (m) the teach's range scan showed at each subgoal in its driving direction (the
    command after it, else the one before; inf: nothing in range), or None when the robot sent no scans.
    The repeat's stop zone never reaches further than what the teach itself drove up to (runtime.safety)."""
    if all(s is None for s in scans):
        return None
    out = np.full(len(scans), np.nan)
    for i, scan in enumerate(scans):
        if scan is None:
            continue
        v = commands[i, 0] if commands[i, 0] != 0 or i == 0 else commands[i - 1, 0]
        seen = limit_twist(-1.0 if v < 0 else 1.0, 0.0, scan).distance
        out[i] = math.inf if seen is None else seen
    return out


# ------------------------------------------------------------------------------------------------- CLI


@dataclass
class TeachRunConfig:
    """Everything `vtr teach` needs."""

    sim: str = opt(help=f"simulator endpoint, e.g. {EXAMPLE}")
    route: str = opt(help="ROUTE.json: start pose and (v, w, duration) segments")
    out: str = opt(help="where to write the route (.npz)")
    teach: TeachConfig = field(default_factory=TeachConfig)  # spacing and control step
    #: Seconds to wait for hello and reset (a step waits its duration + 0.3 s, then a stop); the settings
    #: (runtime/settings.py) give these two and the robot's address, from a flag or the config file.
    timeout_s: float = default("teach.timeout")
    retries: int = default("teach.retries")

    def __post_init__(self) -> None:
        check_endpoint(self.sim)
        if not self.out:
            raise ValueError("--out must be a file path")
        if not self.timeout_s > 0:
            raise ValueError(f"--timeout must be > 0 seconds, got {self.timeout_s}")
        if self.retries < 1:
            raise ValueError(f"--retries must be >= 1, got {self.retries}")


def run(cfg: TeachRunConfig) -> Route:
    from vtr.runtime.client import SimClient
    from vtr.runtime.route_script import load_route_script

    script = load_route_script(cfg.route)
    # a silent robot gets its stop 0.3 s after a step's duration, whatever --timeout allows hello/reset
    with SimClient(cfg.sim, retries=cfg.retries, setup_timeout_s=cfg.timeout_s) as client:
        route = teach(client, script, cfg.teach)
    route.save(cfg.out)
    return route


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_arguments(parser, TeachRunConfig, skip=("sim", "route"))  # optional with --bag
    parser.add_argument("--route", default=None, help="ROUTE.json: start pose and (v, w, duration) segments")
    add_config_arguments(parser, TeachConfig)
    add_settings(
        parser, "teach", notes={"robot.address": "or --bag"}
    )  # --config, --sim (or --bag), --timeout, --retries


def run_cli(args: argparse.Namespace) -> int:
    try:
        settings = resolve(args, "teach", required=False)
        teach_cfg = config_from_args(TeachConfig, args)
        sim = settings["robot.address"]
        if sim is REQUIRED or not args.route:
            raise ValueError("needs --sim and --route (a live robot), or --bag (a recorded drive)")
        cfg = config_from_args(
            TeachRunConfig,
            args,
            sim=sim,
            teach=teach_cfg,
            timeout_s=settings["teach.timeout"],
            retries=settings["teach.retries"],
        )
    except ValueError as exc:
        print(f"vtr teach: {exc}", file=sys.stderr)
        return 2
    try:
        route = run(cfg)
    except (OSError, ValueError, RobotError) as exc:  # bad ROUTE.json, unreachable or refusing simulator
        print(f"vtr teach: {exc}", file=sys.stderr)
        return 2
    print(f"vtr teach: {len(route)} subgoals ({cfg.teach.spacing} spacing) -> {os.path.abspath(cfg.out)}")
    return 0
