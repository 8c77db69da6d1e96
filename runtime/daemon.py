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

from vtr.runtime.controller import ControllerConfig
from vtr.runtime.mcap_log import step_recorder
from vtr.runtime.repeater import RepeatConfig, Repeater, StepRecord, Summary
from vtr.runtime.robot import RobotError


def log_writer(stream: IO[str]) -> Callable[[StepRecord], None]:
    """An ``on_step`` callback writing one JSON line per command sent."""

    def write(record: StepRecord) -> None:
        if record.commanded:
            stream.write(json.dumps(record.to_log(), allow_nan=False, default=float) + "\n")
            stream.flush()

    return write


# ------------------------------------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sim", required=True, help="robot/simulator endpoint, e.g. tcp://127.0.0.1:5555")
    parser.add_argument("--model", required=True, help="VelocityNet ONNX file")
    parser.add_argument("--route", required=True, help="taught route (.npz from `vtr teach`)")
    parser.add_argument("--log", default=None, help="write one JSON line per control step here")
    parser.add_argument(
        "--mcap",
        default=None,
        metavar="PATH",
        help="also write the run as a ROS 2 MCAP bag for Foxglove / ros2 bag play (PATH.mcap: one file; "
        "else a bag folder); needs pip install 'vtr-mpc[ros]'",
    )
    parser.add_argument(
        "--foxglove",
        nargs="?",
        type=int,
        const=8765,
        default=None,
        metavar="PORT",
        help="serve the run live to Foxglove on ws://127.0.0.1:PORT (default port 8765); "
        "needs pip install 'vtr-mpc[foxglove]'",
    )
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument(
        "--e-m",
        type=float,
        default=None,
        help="fixed switch threshold (paper: 17); default: calibrated from the route",
    )
    parser.add_argument("--threads", type=int, default=1, help="onnxruntime intra-op threads")
    parser.add_argument("--max-steps", type=int, default=2000, help="stop after this many control steps")
    parser.add_argument(
        "--stall-steps", type=int, default=None, help="stall guard patience; 0 disables it (default: 10)"
    )
    parser.add_argument(
        "--settle",
        type=int,
        default=None,
        help="extra commands at a subgoal while the error still falls under e_m (default: 2; paper: 0)",
    )
    parser.add_argument(
        "--paper",
        action="store_true",
        help="the paper's Algorithm 1 exactly: e_m 17, no settling, no stall guard",
    )
    parser.add_argument("--localise", action="store_true", help="start at the best-matching subgoal")
    parser.add_argument("--continuous", action="store_true", help="no zero command between control steps")
    parser.add_argument(
        "--start",
        choices=("route", "here"),
        default="route",
        help="route: reset the simulator to the route's first pose first; here: start where the robot is",
    )
    parser.add_argument(
        "--seed", type=int, default=1, help="actuation-noise seed for the reset (--start route)"
    )
    parser.add_argument("--timeout", type=float, default=2.0, help="seconds to wait for each reply")
    parser.add_argument("--retries", type=int, default=3, help="tries per request before giving up")
    parser.add_argument(
        "--frame-timeout", type=float, default=5.0, help="seconds without a valid frame before stopping"
    )


@dataclass
class RepeatRunConfig:
    """Everything `vtr repeat` needs."""

    sim: str  # endpoint
    model: str  # ONNX path
    route: str  # route .npz path
    log: str | None = None  # JSON-lines log path
    mcap: str | None = None  # MCAP run path (runtime.mcap_log)
    foxglove_port: int | None = None  # live view on 127.0.0.1 (runtime.foxglove_live)
    threads: int = 1  # onnxruntime intra-op threads
    timeout_s: float = 2.0  # per-reply timeout
    retries: int = 3  # tries per request
    #: "route": reset the simulator to the route's first pose before repeating; "here": start where it is
    #: (a real robot placed by hand, or a bridge that does not implement reset).
    start: str = "route"
    #: Actuation-noise seed for the reset ("route" start only).
    seed: int | None = 1
    repeat: RepeatConfig = field(default_factory=RepeatConfig)

    def __post_init__(self) -> None:
        if self.start not in ("route", "here"):
            raise ValueError(f"start must be 'route' or 'here', got {self.start!r}")
        if "://" not in self.sim:
            raise ValueError(f"sim must be a ZeroMQ endpoint like tcp://127.0.0.1:5555, got {self.sim!r}")
        if self.threads < 1:
            raise ValueError(f"threads must be >= 1, got {self.threads}")
        if not self.timeout_s > 0:
            raise ValueError(f"timeout_s must be > 0, got {self.timeout_s}")
        if self.retries < 1:
            raise ValueError(f"retries must be >= 1, got {self.retries}")


def run(cfg: RepeatRunConfig, stop_event: threading.Event | None = None) -> Summary:
    from vtr.runtime.client import SimClient
    from vtr.runtime.policy import OnnxPolicy
    from vtr.runtime.route import Route

    policy = OnnxPolicy(cfg.model, threads=cfg.threads)
    route = Route.load(cfg.route)
    policy.check_route(route)
    mcap = None
    if cfg.mcap:
        from vtr.runtime.mcap_log import McapRunWriter

        mcap = McapRunWriter(cfg.mcap)
    live = None
    if cfg.foxglove_port is not None:
        from vtr.runtime.foxglove_live import FoxgloveLive

        live = FoxgloveLive(cfg.foxglove_port)
        print(
            f"vtr repeat: live view for Foxglove on ws://127.0.0.1:{live.port}", file=sys.stderr, flush=True
        )
    log_file = open(cfg.log, "w", encoding="utf-8") if cfg.log else None  # noqa: SIM115
    try:
        with SimClient(cfg.sim, cfg.timeout_s, cfg.retries, expect_shape=policy.image_shape) as client:
            if cfg.start == "route":
                pose = route.poses[0]
                if not np.all(np.isfinite(pose)):
                    raise ValueError("the route's first pose is unknown; use --start here")
                client.reset(pose=(float(pose[0]), float(pose[1]), float(pose[2])), seed=cfg.seed)
            callbacks = [log_writer(log_file)] if log_file is not None else []
            if mcap is not None:
                callbacks.append(step_recorder(mcap, route.images))
            if live is not None:
                callbacks.append(step_recorder(live, route.images))
            on_step = (lambda rec: [cb(rec) for cb in callbacks]) if callbacks else None
            repeater = Repeater(
                client, policy, route, config=cfg.repeat, on_step=on_step, stop_event=stop_event
            )
            summary = repeater.run()
            if log_file is not None:
                log_file.write(json.dumps({"summary": summary.to_dict()}, default=float) + "\n")
            if mcap is not None:
                mcap.record_summary(summary.to_dict())
            return summary
    finally:
        if log_file is not None:
            log_file.close()
        if mcap is not None:
            mcap.close()
        if live is not None:
            live.close()


def run_cli(args: argparse.Namespace) -> int:
    base = ControllerConfig.paper() if args.paper else ControllerConfig()
    controller = replace(
        base,
        e_m_mode="fixed" if args.e_m is not None else base.e_m_mode,
        e_m=args.e_m if args.e_m is not None else base.e_m,
        stall_steps=args.stall_steps if args.stall_steps is not None else base.stall_steps,
        settle_steps=args.settle if args.settle is not None else base.settle_steps,
        localise=args.localise,
        continuous=args.continuous,
    )
    cfg = RepeatRunConfig(
        sim=args.sim,
        model=args.model,
        route=args.route,
        log=args.log,
        mcap=args.mcap,
        foxglove_port=args.foxglove,
        threads=args.threads,
        timeout_s=args.timeout,
        retries=args.retries,
        start=args.start,
        seed=args.seed,
        repeat=RepeatConfig(
            controller=controller, max_steps=args.max_steps, frame_timeout_s=args.frame_timeout
        ),
    )
    stop_event = threading.Event()
    previous = {
        sig: signal.signal(sig, lambda *_: stop_event.set()) for sig in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        summary = run(cfg, stop_event)
    except (OSError, ValueError, RobotError) as exc:  # bad model/route files, refusals: say so, no traceback
        print(f"vtr repeat: {exc}", file=sys.stderr)
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
        )
    return 0 if summary.completed else 1
