"""`vtr repeat`: the robot daemon. It loads the model and the route, connects to the robot, runs the
repeat loop (``runtime.repeater.Repeater``: its docstring has the safety rules) and writes the log; the
loop itself, its decisions and its safety handling live in the Repeater.

The log (``--log``) has one JSON object per control step (a command sent), then ``{"summary": {...}}``, each
line written whole or not at all (runtime/run_log.py; a full disk ends the run, exit 1, naming the file):

- ``step``: control step number; ``stamp``/``pose``: the robot's clock and pose (null when unknown) of
  the image the decisions were taken on;
- ``from_subgoal``: subgoal index before this image was judged; ``advanced``: subgoals reached on it
  (error <= e_m); ``jumped_to``: indices the stall guard or localisation jumped to; ``subgoal``: the
  subgoal steered to; ``error``: that subgoal's image error (0..255); ``e_m``: the threshold in force;
- ``v``, ``w``: the command applied for dt (the first of VelocityNet's N);
- ``latency_ms``: see ``runtime.repeater.StepRecord``.

Subgoals reached on the last image (the run finishing) appear only in the summary.

On a terminal, and unless ``--json``, one live line on stderr shows the run as it goes (runtime/status_line.py):
subgoal i/N, the image match, the localiser's confidence, the command, time against the teach's, or the wait
for a blocked way.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from vtr.runtime.address import check_endpoint
from vtr.runtime.hello import accept_hello, fit_robot, mapping_notes, require_known_fov
from vtr.runtime.repeater import RepeatConfig, Repeater, RepeatStatus, StepRecord, Summary
from vtr.runtime.robot import RobotError
from vtr.runtime.run_log import LogWriteError
from vtr.runtime.run_outputs import OutputWriteError, RunOutputs, check_outputs
from vtr.runtime.safety import SafetyConfig
from vtr.runtime.settings import PROFILES, default
from vtr.runtime.settings_cli import Resolved, resolve
from vtr.runtime.settings_cli import add_arguments as add_settings
from vtr.runtime.status_line import RepeatStatusLine, taught_seconds

# ------------------------------------------------------------------------------------------------- CLI


@dataclass
class RepeatRunConfig:
    """Everything `vtr repeat` needs (built from the settings, ``runtime.settings``, by
    :func:`config_from_settings`; docs/SETTINGS.md says what each is)."""

    sim: str
    model: str
    route: str
    log: str | None = None
    mcap: str | None = None
    foxglove: int | None = None
    threads: int = default("repeat.threads")
    timeout_s: float = default("repeat.timeout")
    retries: int = 3  # tries per request before giving up
    #: "route": reset the simulator to the route's first pose before repeating; "here": start where it is
    #: (a real robot placed by hand, or a bridge that does not implement reset).
    start: str = "route"
    seed: int | None = 1  # actuation-noise seed for the reset (start "route")
    #: "auto": continuous where the robot's hello says it runs on a wall clock (realtime), else stop-and-go;
    #: "stop-and-go" / "continuous": ``repeat.controller.continuous`` as it is.
    motion: str = "stop-and-go"
    #: Recolour the current image to the subgoal's light before the policy (runtime/light.py; the profile's).
    match_light: bool = True
    repeat: RepeatConfig = field(default_factory=RepeatConfig)
    #: A live status line on stderr while it runs (runtime/status_line.py), shown only on a terminal.
    status_line: bool = False

    def __post_init__(self) -> None:
        check_endpoint(self.sim)
        if self.motion not in ("auto", "stop-and-go", "continuous"):
            raise ValueError(f"motion must be auto, stop-and-go or continuous, got {self.motion!r}")
        if self.start not in ("route", "here"):
            raise ValueError(f"start must be 'route' or 'here', got {self.start!r}")
        if self.threads < 1:
            raise ValueError(f"threads must be >= 1, got {self.threads}")
        if not self.timeout_s > 0:
            raise ValueError(f"timeout_s must be > 0 seconds, got {self.timeout_s}")
        if self.retries < 1:
            raise ValueError(f"retries must be >= 1, got {self.retries}")


def run(cfg: RepeatRunConfig, stop_event: threading.Event | None = None) -> Summary:
    from vtr.runtime.client import SimClient
    from vtr.runtime.policy import OnnxPolicy
    from vtr.runtime.route import Route

    check_outputs(cfg.log, cfg.mcap)  # before anything is loaded or created: a bad path is refused first
    policy = OnnxPolicy(cfg.model, threads=cfg.threads)
    route = Route.load(cfg.route)
    require_known_fov(route.camera, cfg.route)
    policy.check_route(route)
    if cfg.match_light:
        from vtr.runtime.light import LightMatchedPolicy

        policy = LightMatchedPolicy(policy)
    with SimClient(
        cfg.sim, cfg.timeout_s, cfg.retries, expect_shape=policy.image_shape, cancel=stop_event
    ) as client:
        # what the robot announces: its limits check every step, its camera must match route and model; an
        # older hello is accepted as `vtr teach` accepts it (runtime.hello.accept_hello), with a warning
        hello, warnings = accept_hello(client.handshake(), route.dt)
        for warning in warnings:
            print(f"vtr repeat: warning: {warning}", file=sys.stderr)
        mapping, notes = fit_robot(hello, route.camera, policy.meta)
        client.map_frames(mapping)  # the camera's frames become the model's input where they enter
        for note in mapping_notes(mapping) + notes:
            print(f"vtr repeat: note: {note}", file=sys.stderr)
        repeat = motion_for_robot(cfg.repeat, cfg.motion, hello.mode)
        if cfg.start == "route":
            pose = route.poses[0]
            if not np.all(np.isfinite(pose)):
                raise ValueError("the route's first pose is unknown; use --start here")
            client.reset(pose=(float(pose[0]), float(pose[1]), float(pose[2])), seed=cfg.seed)
        repeater = Repeater(client, policy, route, config=repeat, stop_event=stop_event)
        # opened only now, with the model, route and robot checked: a refused start leaves no empty file
        with RunOutputs(route.images, cfg.log, cfg.mcap, cfg.foxglove) as outputs:  # log, MCAP bag, live view
            line = status_line(repeater) if cfg.status_line else None
            repeater.on_step = observers(outputs.chain(), line)
            try:
                summary = repeater.run()
            finally:
                if line is not None:
                    line.close()  # what is printed next starts on a line of its own
            outputs.finish(summary.to_dict())
        return summary


def motion_for_robot(repeat: RepeatConfig, motion: str, robot_mode: str | None) -> RepeatConfig:
    """``motion`` "auto": continuous on a robot whose hello says it runs on a wall clock (stopping after each
    step would only make it stand while the next image is judged), stop-and-go on a lockstep or silent one
    (whose clock waits for us anyway: the paper's motion); any other motion leaves ``repeat`` as it is."""
    if motion != "auto":
        return repeat
    return replace(repeat, controller=replace(repeat.controller, continuous=robot_mode == "realtime"))


def status_line(repeater: Repeater) -> RepeatStatusLine:
    """The live line of a repeat: the route's subgoals and taught time, the localiser's confidence."""

    def confidence() -> float | None:
        return getattr(getattr(repeater.controller, "estimate", None), "confidence", None)

    route = repeater.route
    return RepeatStatusLine(len(route), taught_seconds(route), repeater.config.wait_s, confidence)


def observers(*calls: Callable[[StepRecord], None] | None) -> Callable[[StepRecord], None] | None:
    """One ``on_step`` calling each of ``calls`` that is not None, in order (None when there is none)."""
    chosen = [c for c in calls if c is not None]
    if len(chosen) <= 1:
        return chosen[0] if chosen else None

    def on_step(record: StepRecord) -> None:
        for call in chosen:
            call(record)

    return on_step


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_settings(parser, "repeat")  # runtime/settings.py declares them; docs/SETTINGS.md lists them


def config_from_settings(values: Resolved | Mapping[str, Any]) -> RepeatRunConfig:
    """The run's configuration from `vtr repeat`'s settings (names as in ``runtime.settings``)."""
    profile = PROFILES[values["repeat.profile"]]
    controller = profile.controller()
    motion = values["repeat.motion"] or profile.motion
    controller = replace(
        controller, localise=values["repeat.start"] == "anywhere", continuous=motion == "continuous"
    )
    safety = replace(
        SafetyConfig(),
        radius=values["robot.radius"],
        stop_distance=values["repeat.stop_distance"],
        slowdown_distance=values["repeat.slowdown_distance"],
    )
    return RepeatRunConfig(
        sim=values["robot.address"],
        model=values["repeat.model"],
        route=values["repeat.route"],
        log=values["repeat.log"],
        mcap=values["repeat.mcap"],
        foxglove=values["repeat.foxglove"],
        threads=values["repeat.threads"],
        timeout_s=values["repeat.timeout"],
        start="route" if values["repeat.start"] == "route" else "here",
        motion=motion,
        match_light=profile.match_light,
        repeat=RepeatConfig(
            controller=controller, safety=safety, wait_s=values["repeat.wait"], speed=values["repeat.speed"]
        ),
        status_line=not values["repeat.json"],  # and only on a terminal
    )


def run_cli(args: argparse.Namespace) -> int:
    """0: the route was finished; 1: the repeat ended otherwise; 2: refused input; 130: interrupted."""
    try:
        settings = resolve(args, "repeat")
        cfg = config_from_settings(settings)
    except ValueError as exc:
        print(f"vtr repeat: {exc}", file=sys.stderr)
        return 2
    stop_event = threading.Event()
    previous = {
        sig: signal.signal(sig, lambda *_: stop_event.set()) for sig in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        summary = run(cfg, stop_event)
    except (LogWriteError, OutputWriteError) as exc:  # a full disk mid-run: the robot was stopped first
        print(f"vtr repeat: {exc}", file=sys.stderr)
        return 1
    except (OSError, ValueError, RobotError) as exc:  # bad model/route files, refusals: say so, no traceback
        print(f"vtr repeat: {' '.join(str(exc).split())}", file=sys.stderr)
        return 2
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if settings["repeat.json"]:
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
