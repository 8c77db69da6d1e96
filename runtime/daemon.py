"""`vtr repeat`: follow a taught route from camera images alone. The daemon does I/O, timing and logging;
the decisions are the controller's (runtime.controller) and the velocities the policy's (runtime.policy).

Safety rules, in order of precedence:

- zero velocity is commanded when the loop ends for any reason: finished, stalled, step limit,
  SIGINT/SIGTERM (``stop_event``), an exception (re-raised after the stop), or no valid frame;
- a frame that fails validation (``BadFrameError`` from the client, or a wrong shape/dtype from any
  Robot) is counted and never reaches the network: the robot is stopped and re-polled with ``observe``
  until a valid frame arrives, or ``frame_timeout_s`` passes without one (then the run ends);
- the step limit ends a run whose robot is lost.

The log has one JSON object per control step (a command sent), then ``{"summary": {...}}``:

- ``step``: control step number; ``stamp``/``pose``: the robot's clock and pose (null when unknown) of
  the image the decisions were taken on;
- ``from_subgoal``: subgoal index before this image was judged; ``advanced``: subgoals reached on it
  (error <= e_m); ``jumped_to``: indices the stall guard or localisation jumped to; ``subgoal``: the
  subgoal steered to; ``error``: that subgoal's image error (0..255); ``e_m``: the threshold in force;
- ``v``, ``w``: the command applied for dt (the first of VelocityNet's N);
- ``latency_ms``: ``error`` (controller), ``preprocess`` and ``inference`` (policy), ``compute``
  (image in to command ready), ``robot`` (step round trip plus the zero command), ``receive`` and
  ``decode`` (SimClient: the step's reply wait and its validation), ``total``.

Subgoals reached on the last image (the run finishing) appear only in the summary.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from typing import IO, Any

import numpy as np

from vtr.runtime.controller import Action, Controller, ControllerConfig
from vtr.runtime.protocol import BadFrameError
from vtr.runtime.robot import Observation, Robot, RobotError


@dataclass
class RepeatConfig:
    """Daemon settings."""

    #: Subgoal switching (Algorithm 1 and its extensions).
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    #: Seconds each command is applied for; None takes the model's metadata dt (the paper's 0.1 s).
    dt: float | None = None
    #: Control steps (commands sent) before giving up: a lost robot must stop.
    max_steps: int = 2000
    #: Seconds without a valid frame before the run ends.
    frame_timeout_s: float = 5.0
    #: Pause between re-polls after a bad frame, in seconds.
    bad_frame_backoff_s: float = 0.05

    def __post_init__(self) -> None:
        if self.dt is not None and not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {self.dt!r}")
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        if not self.frame_timeout_s > 0:
            raise ValueError(f"frame_timeout_s must be > 0, got {self.frame_timeout_s}")
        if self.bad_frame_backoff_s < 0:
            raise ValueError(f"bad_frame_backoff_s must be >= 0, got {self.bad_frame_backoff_s}")


@dataclass
class RepeatSummary:
    """How a repeat ended. ``reason``: finished | stalled | lost | collided | step_limit | interrupted |
    no_valid_frame | robot_error."""

    completed: bool
    reason: str
    steps: int
    subgoals_reached: int
    subgoals_total: int
    e_m: float
    sim_time_s: float
    wall_time_s: float
    bad_frames: int
    nonfinite_outputs: int
    jumps: int
    localised_to: int | None
    plateaus: int = 0  # subgoals the stall guard accepted next to, at error <= jump_factor * e_m
    detail: str = ""
    mean_latency_ms: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class _NoValidFrame(Exception):
    pass


def _safe_stop(robot: Robot) -> bool:
    """Command zero velocity; never raises (the robot may be the thing that failed)."""
    try:
        robot.stop()
        return True
    except Exception:
        return False


def _emit(log: IO[str] | Callable[[dict[str, Any]], None] | None, record: dict[str, Any]) -> None:
    if log is None:
        return
    if callable(log):
        log(record)
        return
    log.write(json.dumps(record, allow_nan=False, default=float) + "\n")
    log.flush()


def repeat(
    robot: Robot,
    policy: Any,
    route: Any,
    cfg: RepeatConfig | None = None,
    log: IO[str] | Callable[[dict[str, Any]], None] | None = None,
    stop_event: threading.Event | None = None,
) -> RepeatSummary:
    """Follow ``route`` with ``policy`` on ``robot``; returns how it ended. See the module docstring.

    ``policy`` needs ``predict(current, subgoal) -> (2, N)``, ``image_shape`` and ``nonfinite_count``
    (``OnnxPolicy``); its ``last_timing_ms`` is logged when present. ``log`` is a text file (one JSON
    object per line) or a callable taking each record.
    """
    cfg = cfg or RepeatConfig()
    if hasattr(policy, "check_route"):
        policy.check_route(route)
    dt = cfg.dt if cfg.dt is not None else float(getattr(getattr(policy, "meta", None), "dt", 0.1))
    controller = Controller(route.images, cfg.controller)
    expect = (*route.images.shape[1:3], 3)
    stop_event = stop_event or threading.Event()
    bad_frames = 0
    steps = 0
    first_stamp: float | None = None
    last_stamp: float | None = None
    totals: dict[str, float] = {}
    t_start = time.perf_counter()
    last_valid = time.monotonic()
    reason, detail, last_rejected = "", "", ""

    def valid(obs: Observation) -> bool:
        nonlocal bad_frames, last_rejected
        image = obs.image
        if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.shape != expect:
            shape = getattr(image, "shape", None)
            last_rejected = (
                f"image {shape} {getattr(image, 'dtype', type(image).__name__)}, expected {expect} uint8"
            )
        elif not math.isfinite(obs.stamp):
            last_rejected = f"non-finite stamp {obs.stamp}"
        else:
            return True
        bad_frames += 1
        return False

    def fetch(call: Callable[[], Observation]) -> Observation:
        """A valid frame from ``call``, else stop the robot and re-poll observe() until the deadline."""
        nonlocal bad_frames, last_valid, last_rejected
        while True:
            try:
                obs = call()
                if valid(obs):
                    last_valid = time.monotonic()
                    return obs
            except BadFrameError as exc:
                bad_frames += 1
                last_rejected = str(exc)
            _safe_stop(robot)
            if time.monotonic() - last_valid > cfg.frame_timeout_s or stop_event.is_set():
                raise _NoValidFrame()
            time.sleep(cfg.bad_frame_backoff_s)
            call = robot.observe

    try:
        obs = fetch(robot.observe)
        first_stamp = last_stamp = obs.stamp
        while True:
            if stop_event.is_set():
                reason = "interrupted"
                break
            t0 = time.perf_counter()
            from_subgoal, advances, jumps = controller.index, 0, []
            while True:
                decision = controller.decide(obs.image, obs.collided)
                if decision.action is Action.ADVANCE:
                    advances += 1
                    continue
                if decision.action is Action.JUMP:
                    jumps.append(decision.index)
                    continue
                break
            t_error = time.perf_counter() - t0
            if decision.action is Action.FINISHED:
                reason = "finished"
                break
            if decision.action in (Action.STALLED, Action.LOST, Action.COLLIDED):
                reason, detail = decision.action.value, decision.note
                break
            if steps >= cfg.max_steps:
                reason = "step_limit"
                break
            velocities = policy.predict(obs.image, controller.subgoal)
            v, w = float(velocities[0, 0]), float(velocities[1, 0])
            t_policy = time.perf_counter()
            stage = dict(getattr(policy, "last_timing_ms", {}) or {})
            stage["error"] = t_error * 1e3
            stage["compute"] = (t_policy - t0) * 1e3
            record = {
                "step": steps,
                "subgoal": decision.index,
                "from_subgoal": from_subgoal,
                "advanced": advances,
                "jumped_to": jumps,
                "error": round(decision.error, 4),
                "e_m": round(controller.e_m, 4),
                "v": v,
                "w": w,
                "stamp": obs.stamp,
                "pose": list(obs.pose) if obs.pose is not None else None,
            }
            new_obs = fetch(lambda v=v, w=w: robot.step(v, w, dt))
            # the robot's own breakdown of the step round trip (SimClient: receive, decode)
            robot_stage = {k: float(x) for k, x in (getattr(robot, "last_timing_ms", {}) or {}).items()}
            if decision.then_stop:
                robot.stop()
            t_end = time.perf_counter()
            stage["robot"] = (t_end - t_policy) * 1e3
            stage.update(robot_stage)
            stage["total"] = (t_end - t0) * 1e3
            record["latency_ms"] = {k: round(x, 4) for k, x in stage.items()}
            for k, x in stage.items():
                totals[k] = totals.get(k, 0.0) + x
            _emit(log, record)
            steps += 1
            obs = new_obs
            last_stamp = obs.stamp
    except _NoValidFrame:
        if stop_event.is_set():
            reason = "interrupted"
        else:
            reason, detail = (
                "no_valid_frame",
                f"no valid frame for {cfg.frame_timeout_s} s; last rejected: {last_rejected}",
            )
    except RobotError as exc:
        reason, detail = "robot_error", str(exc)
    except KeyboardInterrupt:
        reason = "interrupted"
    finally:
        _safe_stop(robot)

    reached = min(controller.index, len(controller))
    summary = RepeatSummary(
        completed=reason == "finished",
        reason=reason,
        steps=steps,
        subgoals_reached=reached,
        subgoals_total=len(controller),
        e_m=controller.e_m,
        sim_time_s=(last_stamp - first_stamp) if first_stamp is not None and last_stamp is not None else 0.0,
        wall_time_s=time.perf_counter() - t_start,
        bad_frames=bad_frames,
        nonfinite_outputs=int(getattr(policy, "nonfinite_count", 0)),
        jumps=controller.jumps,
        localised_to=controller.localised_to,
        plateaus=controller.plateaus,
        detail=detail,
        mean_latency_ms={k: round(x / steps, 4) for k, x in totals.items()} if steps else {},
    )
    _emit(log, {"summary": summary.to_dict()})
    return summary


# ------------------------------------------------------------------------------------------------- CLI


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--sim", required=True, help="robot/simulator endpoint, e.g. tcp://127.0.0.1:5555")
    parser.add_argument("--model", required=True, help="VelocityNet ONNX file")
    parser.add_argument("--route", required=True, help="taught route (.npz from `vtr teach`)")
    parser.add_argument("--log", default=None, help="write one JSON line per control step here")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.add_argument(
        "--e-m",
        type=float,
        default=None,
        help="fixed switch threshold (paper: 17 with --match raw); default: one per subgoal from the route",
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
        help="extra commands at a subgoal while the error still falls under e_m (default: 1; paper: 0)",
    )
    parser.add_argument(
        "--paper",
        action="store_true",
        help="the paper's Algorithm 1 exactly: raw error, e_m 17, no settling, stall guard or lost test",
    )
    parser.add_argument(
        "--match",
        choices=("patch", "raw"),
        default=None,
        help="image comparison: patch-normalised median (default) or raw mean abs error (paper)",
    )
    parser.add_argument(
        "--lost-steps",
        type=int,
        default=None,
        help="stop as lost after this many steps with no nearby subgoal matching; 0 disables (default: 5)",
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


def run(cfg: RepeatRunConfig, stop_event: threading.Event | None = None) -> RepeatSummary:
    from vtr.runtime.client import SimClient
    from vtr.runtime.policy import OnnxPolicy
    from vtr.runtime.route import Route

    policy = OnnxPolicy(cfg.model, threads=cfg.threads)
    route = Route.load(cfg.route)
    policy.check_route(route)
    log_file = open(cfg.log, "w", encoding="utf-8") if cfg.log else None  # noqa: SIM115
    try:
        with SimClient(cfg.sim, cfg.timeout_s, cfg.retries, expect_shape=policy.image_shape) as client:
            if cfg.start == "route":
                pose = route.poses[0]
                if not np.all(np.isfinite(pose)):
                    raise ValueError("the route's first pose is unknown; use --start here")
                client.reset(pose=(float(pose[0]), float(pose[1]), float(pose[2])), seed=cfg.seed)
            return repeat(client, policy, route, cfg.repeat, log_file, stop_event)
    finally:
        if log_file is not None:
            log_file.close()


def run_cli(args: argparse.Namespace) -> int:
    base = ControllerConfig.paper() if args.paper else ControllerConfig()
    controller = replace(
        base,
        e_m_mode="fixed" if args.e_m is not None else base.e_m_mode,
        e_m=args.e_m if args.e_m is not None else base.e_m,
        stall_steps=args.stall_steps if args.stall_steps is not None else base.stall_steps,
        settle_steps=args.settle if args.settle is not None else base.settle_steps,
        match=replace(base.match, method=args.match) if args.match is not None else base.match,
        lost_steps=args.lost_steps if args.lost_steps is not None else base.lost_steps,
        localise=args.localise,
        continuous=args.continuous,
    )
    cfg = RepeatRunConfig(
        sim=args.sim,
        model=args.model,
        route=args.route,
        log=args.log,
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
            f"vtr repeat: {s.reason}{' (' + s.detail + ')' if s.detail else ''}; {s.subgoals_reached}/{s.subgoals_total} "
            f"subgoals, {s.steps} steps, e_m={s.e_m:.2f}, simulated {s.sim_time_s:.1f} s, wall {s.wall_time_s:.1f} s, "
            f"bad frames {s.bad_frames}, non-finite outputs {s.nonfinite_outputs}"
        )
    return 0 if summary.completed else 1
