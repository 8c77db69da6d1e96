"""`vtr repeat`: the robot daemon. It loads the model and the route, connects to the robot, runs the
repeat loop (``runtime.repeater.Repeater``: its docstring has the safety rules) and writes the log; the
loop itself, its decisions and its safety handling live in the Repeater.

The log (``--log``) has one JSON object per control step (a command sent), then ``{"summary": {...}}``:

- ``step``: control step number; ``stamp``/``pose``: the robot's clock and pose (null when unknown) of
  the image the decisions were taken on;
- ``from_subgoal``: subgoal index before this image was judged; ``advanced``: subgoals reached on it
  (error <= e_m); ``jumped_to``: indices the stall guard or localisation jumped to; ``subgoal``: the
  subgoal steered to; ``error``: that subgoal's image error (0..255); ``e_m``: the threshold in force;
- ``v``, ``w``: the command applied for dt (the first of VelocityNet's N);
- ``latency_ms``: see ``runtime.repeater.StepRecord``.

Subgoals reached on the last image (the run finishing) appear only in the summary.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import IO

import numpy as np

from vtr.runtime.address import EXAMPLE, check_endpoint
from vtr.runtime.cliargs import add_config_arguments, config_from_args, opt
from vtr.runtime.controller import ControllerConfig
from vtr.runtime.hello import check_robot_fits
from vtr.runtime.repeater import RepeatConfig, Repeater, RepeatStatus, StepRecord, Summary
from vtr.runtime.robot import RobotError
from vtr.runtime.run_outputs import RunOutputs


def log_writer(stream: IO[str]) -> Callable[[StepRecord], None]:
    """An ``on_step`` callback writing one JSON line per command sent."""

    def write(record: StepRecord) -> None:
        if record.commanded:
            stream.write(json.dumps(record.to_log(), allow_nan=False, default=float) + "\n")
            stream.flush()

    return write


# ------------------------------------------------------------------------------------------------- CLI


@dataclass
class RepeatRunConfig:
    """Everything `vtr repeat` needs."""

    sim: str = opt(help=f"robot/simulator endpoint, e.g. {EXAMPLE}")
    model: str = opt(help="VelocityNet ONNX file")
    route: str = opt(help="taught route (.npz from `vtr teach`)")
    log: str | None = opt(None, "write one JSON line per control step here, then the summary")
    threads: int = opt(1, "onnxruntime intra-op threads")
    timeout_s: float = opt(
        0.3,
        "seconds to wait for a reply beyond the step's own duration; then a stop is sent",
        flag="--timeout",
    )
    retries: int = opt(3, "tries per request before giving up")
    #: "route": reset the simulator to the route's first pose before repeating; "here": start where it is
    #: (a real robot placed by hand, or a bridge that does not implement reset).
    start: str = opt(
        "route",
        "route: reset the simulator to the route's first pose first; here: start where the robot is",
        choices=("route", "here"),
    )
    seed: int | None = opt(1, "actuation-noise seed for the reset (--start route)")
    match_light: bool = opt(
        True,
        "recolour the current image to the subgoal's light before the policy (runtime/light.py; off with --paper)",
    )
    mcap: str | None = opt(
        None,
        "also write the run as a ROS 2 MCAP bag for Foxglove and ros2 bag play (PATH.mcap: one file, else a "
        "bag folder); needs pip install 'vtr-mpc[ros]'",
        metavar="PATH",
    )
    foxglove: int | None = opt(
        None,
        "serve the run live to Foxglove on ws://127.0.0.1:PORT; needs pip install 'vtr-mpc[foxglove]'",
        metavar="PORT",
    )
    repeat: RepeatConfig = field(default_factory=RepeatConfig)

    def __post_init__(self) -> None:
        check_endpoint(self.sim)
        if self.start not in ("route", "here"):
            raise ValueError(f"start must be 'route' or 'here', got {self.start!r}")
        if self.threads < 1:
            raise ValueError(f"--threads must be >= 1, got {self.threads}")
        if not self.timeout_s > 0:
            raise ValueError(f"--timeout must be > 0 seconds, got {self.timeout_s}")
        if self.retries < 1:
            raise ValueError(f"--retries must be >= 1, got {self.retries}")


def run(cfg: RepeatRunConfig, stop_event: threading.Event | None = None) -> Summary:
    from vtr.runtime.client import SimClient
    from vtr.runtime.policy import OnnxPolicy
    from vtr.runtime.route import Route

    policy = OnnxPolicy(cfg.model, threads=cfg.threads)
    route = Route.load(cfg.route)
    policy.check_route(route)
    if cfg.match_light:
        from vtr.runtime.light import LightMatchedPolicy

        policy = LightMatchedPolicy(policy)
    with SimClient(
        cfg.sim, cfg.timeout_s, cfg.retries, expect_shape=policy.image_shape, cancel=stop_event
    ) as client:
        # what the robot announces: its limits check every step, its camera must match route and model
        for note in check_robot_fits(client.handshake(), route.camera, policy.meta):
            print(f"vtr repeat: note: {note}", file=sys.stderr)
        if cfg.start == "route":
            pose = route.poses[0]
            if not np.all(np.isfinite(pose)):
                raise ValueError("the route's first pose is unknown; use --start here")
            client.reset(pose=(float(pose[0]), float(pose[1]), float(pose[2])), seed=cfg.seed)
        repeater = Repeater(client, policy, route, config=cfg.repeat, stop_event=stop_event)
        with RunOutputs(cfg.mcap, cfg.foxglove, route.images) as outputs:  # MCAP bag, live view
            if cfg.log is None:
                repeater.on_step = outputs.chain()
                summary = repeater.run()
            else:
                # opened only now, with the model, route and robot checked: a refused start leaves no empty log
                with open(cfg.log, "w", encoding="utf-8") as log_file:
                    repeater.on_step = outputs.chain(log_writer(log_file))
                    summary = repeater.run()
                    log_file.write(json.dumps({"summary": summary.to_dict()}, default=float) + "\n")
            outputs.finish(summary.to_dict())
        return summary


#: ControllerConfig fields a flag sets as given (flag, field, type, help; the help gets the default appended).
_OVERRIDES: tuple[tuple[str, str, type, str], ...] = (
    ("--lost-steps", "lost_steps", int,
     "stop as lost after this many steps with no nearby subgoal matching; 0 disables"),
    ("--stall-steps", "stall_steps", int, "stall guard patience; 0 disables it"),
    ("--settle", "settle_steps", int, "extra commands at a subgoal while the error still falls (paper: 0)"),
    ("--progress-gate", "progress_gate", float,
     "switch past a subgoal only after commanding this fraction of the taught travel into it; 0 disables"),
    ("--taught-prior", "taught_prior", float,
     "blend the taught command into each subgoal with the policy's at this weight, 0..1"),
    ("--zero-bias", "zero_bias", float,
     "subtract this fraction (0..1) of the policy's command on the subgoal image itself from each command toward it"),
)  # fmt: skip


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_arguments(parser, RepeatRunConfig)
    add_config_arguments(parser, RepeatConfig)
    default = ControllerConfig()
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument(
        "--e-m",
        type=float,
        default=None,
        help="fixed switch threshold (paper: 17 with --match raw); default: calibrated from the route",
    )
    parser.add_argument(
        "--match",
        choices=("patch", "raw"),
        default=None,
        help=f"image comparison: patch-normalised median or the paper's raw mean abs error (default: {default.match.method})",
    )
    for flag, field_name, kind, text in _OVERRIDES:
        parser.add_argument(
            flag,
            type=kind,
            default=None,
            dest=field_name,
            metavar=flag[2:].upper().replace("-", "_"),
            help=f"{text} (default: {getattr(default, field_name)})",
        )
    parser.add_argument(
        "--thresholds",
        choices=("calibrated", "per_subgoal", "hybrid"),
        default=None,
        help="calibrated: one switch threshold for the route; per_subgoal: one per subgoal, with the relative "
        "switch; hybrid: the route's, raised where both gaps around a subgoal are wide "
        f"(default: {default.e_m_mode})",
    )
    parser.add_argument(
        "--paper",
        action="store_true",
        help="the paper's Algorithm 1 exactly: raw error, e_m 17, no settling, stall guard, lost or contact stop",
    )
    parser.add_argument("--localise", action="store_true", help="start at the best-matching subgoal")
    parser.add_argument("--continuous", action="store_true", help="no zero command between control steps")


def controller_from_args(args: argparse.Namespace) -> ControllerConfig:
    base = ControllerConfig.paper() if args.paper else ControllerConfig()
    if args.thresholds is not None and args.e_m is None:  # the relative switch goes with per-subgoal ones
        per_subgoal = args.thresholds == "per_subgoal"
        base = replace(base, e_m_mode=args.thresholds, pass_ratio=1.0 if per_subgoal else 0.0)
    return replace(
        base,
        e_m_mode="fixed" if args.e_m is not None else base.e_m_mode,
        e_m=args.e_m if args.e_m is not None else base.e_m,
        match=replace(base.match, method=args.match) if args.match is not None else base.match,
        **{f: getattr(args, f) for _, f, _, _ in _OVERRIDES if getattr(args, f) is not None},
        localise=args.localise,
        continuous=args.continuous,
    )


def run_cli(args: argparse.Namespace) -> int:
    """0: the route was finished; 1: the repeat ended otherwise; 2: refused input; 130: interrupted."""
    try:
        repeat_cfg = config_from_args(RepeatConfig, args, controller=controller_from_args(args))
        cfg = config_from_args(RepeatRunConfig, args, repeat=repeat_cfg)
        if args.paper:  # Algorithm 1 exactly: the network sees the camera image as it is
            cfg = replace(cfg, match_light=False)
    except ValueError as exc:
        print(f"vtr repeat: {exc}", file=sys.stderr)
        return 2
    stop_event = threading.Event()
    previous = {
        sig: signal.signal(sig, lambda *_: stop_event.set()) for sig in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        summary = run(cfg, stop_event)
    except (OSError, ValueError, RobotError) as exc:  # bad model/route files, refusals: say so, no traceback
        print(f"vtr repeat: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if args.json:
        print(json.dumps(summary.to_dict()))
    else:
        s = summary
        print(
            f"vtr repeat: {s.status.value}{' (' + s.detail + ')' if s.detail else ''}; {s.subgoals_reached}/{s.subgoals_total} "
            f"subgoals, {s.steps} steps, e_m={s.e_m:.2f}, simulated {s.sim_time_s:.1f} s, wall {s.wall_time_s:.1f} s, "
            f"bad frames {s.bad_frames}, non-finite outputs {s.nonfinite_outputs}"
            + (f", re-localised after {s.robot_restarts} robot restart(s)" if s.robot_restarts else "")
        )
    if summary.status is RepeatStatus.INTERRUPTED:
        return 130
    return 0 if summary.completed else 1
