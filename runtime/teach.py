"""`vtr teach`: drive a route and record its visual trajectory (a Route .npz): a scripted route (ROUTE.json,
here), a drive by keyboard in this terminal (``--drive``) or a drive by the robot's own joystick (``--follow``;
both in ``runtime.teach_drive``), all recorded by one recorder (``runtime.teach_record``).

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
from typing import Any, TextIO

import numpy as np

from vtr.runtime.address import EXAMPLE, check_endpoint
from vtr.runtime.cliargs import add_config_arguments, config_from_args, opt
from vtr.runtime.contracts import CONTROL_DT
from vtr.runtime.hello import accept_hello, current_camera_names, fit_model, mapping_notes
from vtr.runtime.kinematics import wrap_angle
from vtr.runtime.preprocess import image_error
from vtr.runtime.protocol import Limits, jsonable
from vtr.runtime.robot import Observation, ResettableRobot, RobotError
from vtr.runtime.route import Route
from vtr.runtime.route_script import RouteScript
from vtr.runtime.setting_spec import REQUIRED
from vtr.runtime.settings import default
from vtr.runtime.settings_cli import add_arguments as add_settings
from vtr.runtime.settings_cli import resolve
from vtr.runtime.teach_drive import drive, follow
from vtr.runtime.teach_record import TeachRecorder, taught_clearance  # noqa: F401  (re-exported)
from vtr.runtime.teleop_keys import FOLLOW_HELP, HELP, KeyReader, raw_terminal

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
        return dist >= self.min_distance or abs(wrap_angle(obs.pose[2] - last_pose[2])) >= self.min_angle


def _current_names(info: dict[str, Any]) -> dict[str, Any]:
    """``info`` with its camera's keys under their current names (``hello.current_camera_names``), as a
    checked hello gives them: the simulator's ``camera_height`` recorded as ``height_m`` (read by the floor
    geometry, ``route_sensing.floor_camera``)."""
    camera = info.get("camera")
    return {**info, "camera": current_camera_names(camera)} if isinstance(camera, dict) else info


def _robot_info(robot: Any, dt: float, model: Any = None) -> dict[str, Any]:
    """Camera/map description from the robot, when it offers one (SimClient's hello, LocalRobot.sim.info).

    A protocol robot's hello is checked as `vtr repeat` checks it (``runtime.hello.accept_hello``): a broken
    hello is refused, an older one accepted with a warning naming what it should add. With ``model`` (a
    ModelMeta) its frames are mapped to the model's input as `vtr repeat` maps them (runtime.hello.fit_model:
    a camera the model was not trained on is refused), and the route records the camera the model sees, with
    the robot's own under ``native``."""
    if hasattr(robot, "handshake"):
        hello, warnings = accept_hello(robot.handshake(), dt)
        for warning in warnings:
            print(f"vtr teach: warning: {warning}", file=sys.stderr)
        info = dict(hello.info)
        # the hello schema (docs/PROTOCOL.md) puts camera and map at the top level; info is free-form
        info["camera"] = {k: v for k, v in dataclasses.asdict(hello.camera).items() if v is not None}
        if model is not None:
            mapping, notes = fit_model(hello.camera, model)
            robot.map_frames(mapping)
            for note in mapping_notes(mapping) + notes:
                print(f"vtr teach: note: {note}", file=sys.stderr)
            if not mapping.identity:
                seen = mapping.camera(hello.camera.height_m)
                native = info["camera"]
                info["camera"] = {k: v for k, v in dataclasses.asdict(seen).items() if v is not None}
                info["camera"].update(native=native, crop=[round(c, 3) for c in mapping.crop])
        if hello.map is not None:
            info["map"] = hello.map
        return info
    timeouts = getattr(robot, "timeouts", 0)
    try:
        if hasattr(robot, "hello"):
            header = robot.hello()
            info = dict(header.get("info") or {})
            info.update({k: header[k] for k in ("camera", "map") if header.get(k) is not None})
            return _current_names(info)
        sim = getattr(robot, "sim", None)
        if sim is not None and hasattr(sim, "info"):
            return _current_names(dict(jsonable(sim.info())))
    except RobotError:
        if getattr(robot, "timeouts", 0) > timeouts:
            raise  # nothing answers: say so now, not after a second round of tries on reset
        return {}  # a bridge that does not implement hello
    except Exception:
        return {}
    return {}


def teach(
    robot: ResettableRobot, script: RouteScript, cfg: TeachConfig | None = None, model: Any = None
) -> Route:
    """Drive ``script`` on ``robot`` and return the recorded Route (not yet saved); ``model`` (a ModelMeta):
    the frames are mapped to its input (``_robot_info``)."""
    cfg = cfg or TeachConfig()
    info = _robot_info(robot, cfg.dt, model)
    recorder = TeachRecorder(cfg, robot.reset(pose=script.start, seed=cfg.seed))
    for segment in script.segments:
        for _ in range(max(1, round(segment.duration / cfg.dt))):
            recorder.step(segment.v, segment.w, robot.step(segment.v, segment.w, cfg.dt))
    robot.stop()
    return recorder.finish(script.name, info)


# ------------------------------------------------------------------------------------------------- CLI


@dataclass
class TeachRunConfig:
    """Everything `vtr teach` needs."""

    sim: str = opt(help=f"simulator endpoint, e.g. {EXAMPLE}")
    route: str = opt(help="ROUTE.json: start pose and (v, w, duration) segments")
    out: str = opt(help="where to write the route (.npz)")
    model: str | None = opt(
        None,
        "the VelocityNet ONNX the route is for: the camera's frames are mapped to its input as `vtr repeat` "
        "maps them (docs/PROTOCOL.md, 'hello') (default: none, frames kept as the camera gives them)",
        metavar="PATH",
    )
    teach: TeachConfig = field(default_factory=TeachConfig)  # spacing and control step
    #: Seconds to wait for hello and reset (a step waits its duration + 0.3 s, then a stop); the settings
    #: (runtime/settings.py) give these two and the robot's address, from a flag or the config file.
    timeout_s: float = default("teach.timeout")
    retries: int = default("teach.retries")
    #: Who drives: "script" (the ROUTE.json), "drive" (keys in this terminal), "follow" (the robot's own driver).
    mode: str = "script"

    def __post_init__(self) -> None:
        check_endpoint(self.sim)
        if not self.out:
            raise ValueError("--out must be a file path")
        if not self.timeout_s > 0:
            raise ValueError(f"--timeout must be > 0 seconds, got {self.timeout_s}")
        if self.retries < 1:
            raise ValueError(f"--retries must be >= 1, got {self.retries}")
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")


MODES = ("script", "drive", "follow")


def model_meta(path: str | None) -> Any:
    """The ModelMeta of the model a route is taught for (None: no model given)."""
    if path is None:
        return None
    from vtr.runtime.policy import OnnxPolicy

    return OnnxPolicy(path).meta


def run(cfg: TeachRunConfig) -> Route | None:
    """Teach and save; None when a drive was aborted (nothing saved)."""
    from vtr.runtime.client import SimClient
    from vtr.runtime.route_script import load_route_script

    if cfg.mode != "script":
        return run_driven(cfg)
    script = load_route_script(cfg.route)
    # a silent robot gets its stop 0.3 s after a step's duration, whatever --timeout allows hello/reset
    model = model_meta(cfg.model)
    with SimClient(cfg.sim, retries=cfg.retries, setup_timeout_s=cfg.timeout_s) as client:
        route = teach(client, script, cfg.teach, model)
    route.save(cfg.out)
    return route


def run_driven(
    cfg: TeachRunConfig, stdin: TextIO | None = None, stdout: TextIO | None = None
) -> Route | None:
    """`vtr teach --drive` / `--follow` (runtime.teach_drive): keys from ``stdin``, which must be a terminal."""
    from vtr.runtime.client import SimClient

    stdin, stdout = stdin or sys.stdin, stdout or sys.stdout
    try:
        fd = stdin.fileno()
    except (OSError, ValueError, AttributeError):  # a pseudo-file (a test's or a notebook's stdin)
        fd = -1
    if fd < 0 or not os.isatty(fd):
        raise ValueError(f"--{cfg.mode} reads keys from a terminal, and stdin is not one")
    model = model_meta(cfg.model)
    with SimClient(cfg.sim, retries=cfg.retries, setup_timeout_s=cfg.timeout_s) as client:
        info = _robot_info(client, cfg.teach.dt, model)
        hello = client.hello_info
        first = client.observe()
        if cfg.mode == "follow" and (hello is None or hello.twist is None) and first.pose is None:
            raise ValueError(
                "--follow needs a robot that reports its executed twist (hello 'twist') or its pose; "
                "this one reports neither (docs/PROTOCOL.md, 'Executed twist')"
            )
        with raw_terminal(fd):  # raw before the keys are shown: a key pressed on seeing them is read at once
            help_line = HELP if cfg.mode == "drive" else FOLLOW_HELP
            print(f"vtr teach --{cfg.mode}: {help_line}", file=stdout, end="\r\n", flush=True)
            keys = KeyReader(fd)
            if cfg.mode == "drive":
                rec = drive(client, cfg.teach, keys, client.limits or Limits(), stdout, first)
            else:
                rec = follow(client, cfg.teach, keys, stdout, first)
    if rec is None:
        return None
    if len(rec) < 2 and rec.since == 0:
        raise ValueError("nothing was driven: the route would be a single view; nothing saved")
    route = rec.finish(os.path.splitext(os.path.basename(cfg.out))[0] or "route", info)
    route.save(cfg.out)
    return route


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_arguments(parser, TeachRunConfig, skip=("sim", "route"))  # optional with --bag
    how = parser.add_mutually_exclusive_group()
    how.add_argument("--route", default=None, help="ROUTE.json: start pose and (v, w, duration) segments")
    how.add_argument(
        "--drive", action="store_true", help=f"drive with the keyboard in this terminal and record: {HELP}"
    )
    how.add_argument(
        "--follow",
        action="store_true",
        help="record while the robot is driven by its own joystick (sends no motion command; q or Enter saves)",
    )
    add_config_arguments(parser, TeachConfig)
    add_settings(
        parser, "teach", notes={"robot.address": "or --bag"}
    )  # --config, --sim (or --bag), --timeout, --retries


def run_cli(args: argparse.Namespace) -> int:
    mode = (
        "drive" if getattr(args, "drive", False) else "follow" if getattr(args, "follow", False) else "script"
    )
    try:
        settings = resolve(args, "teach", required=False)
        teach_cfg = config_from_args(TeachConfig, args)
        sim = settings["robot.address"]
        if sim is REQUIRED or (mode == "script" and not args.route):
            raise ValueError(
                "needs --sim and one of --route (a scripted drive), --drive (keys) or --follow (the robot's own "
                "driver), or --bag (a recorded drive)"
            )
        cfg = config_from_args(
            TeachRunConfig,
            args,
            sim=sim,
            route=args.route or "",
            teach=teach_cfg,
            timeout_s=settings["teach.timeout"],
            retries=settings["teach.retries"],
            mode=mode,
        )
    except ValueError as exc:
        print(f"vtr teach: {exc}", file=sys.stderr)
        return 2
    try:
        route = run(cfg)
    except KeyboardInterrupt:  # Ctrl-C outside raw mode, SIGTERM, SIGHUP: the robot got its stop already
        print("vtr teach: interrupted; nothing saved", file=sys.stderr)
        return 130
    except (OSError, ValueError, RobotError) as exc:  # bad ROUTE.json, unreachable or refusing simulator
        print(f"vtr teach: {exc}", file=sys.stderr)
        return 2
    if route is None:
        print("vtr teach: aborted; nothing saved", file=sys.stderr)
        return 130
    print(f"vtr teach: {len(route)} subgoals ({cfg.teach.spacing} spacing) -> {os.path.abspath(cfg.out)}")
    return 0
