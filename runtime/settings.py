"""The settings a robot owner sets, declared once: `vtr repeat`'s flags and `--help`, the config file
(`--config robot.toml`, also read by `vtr teach` and `vtr check-robot`) and docs/SETTINGS.md all come from
:data:`SETTINGS` (``runtime.settings_cli`` turns it into flags, reads the file and writes the docs).

Each :class:`Setting` lives in a table of the file: ``[robot]`` holds what describes the robot and every
command reads it; ``[repeat]``, ``[teach]`` and ``[check-robot]`` hold one command's settings. Its flag is
``--key`` (dashes for underscores) unless it says otherwise; ``goes`` names where the value ends up.

What only the evaluation's ablations vary (thresholds, the stall guard, settling, the progress gate, the
zero bias, the taught prior, the matching method) is not here: ``ControllerConfig`` and
``evaluation/condition_run.py``'s ``CONTROLLERS`` reach it. ``--profile`` picks a whole controller instead
(:data:`PROFILES`): ``default`` or ``paper`` (Algorithm 1 exactly).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

from vtr.runtime.address import EXAMPLE, check_endpoint
from vtr.runtime.controller_config import ControllerConfig
from vtr.runtime.repeat_types import RepeatConfig
from vtr.runtime.safety import SafetyConfig
from vtr.runtime.setting_spec import Setting

#: The config file's tables, in the order the docs show them; a command reads [robot] and its own.
SECTIONS = ("robot", "repeat", "teach", "check-robot")


class Profile(NamedTuple):
    controller: Callable[[], ControllerConfig]
    match_light: bool  # recolour the current image to the subgoal's light before the policy (runtime.light)
    help: str
    #: The motion when none is set: "auto" follows the robot's clock (continuous where hello says realtime:
    #: on a wall clock a stop after each step only makes the robot wait for the next image; stop-and-go on a
    #: lockstep robot, whose clock waits anyway), else a fixed motion.
    motion: str = "auto"


#: Named controllers (`--profile`): a whole configuration each, never a coupling between flags.
PROFILES: dict[str, Profile] = {
    "default": Profile(
        ControllerConfig,
        True,
        "the route localiser picks the subgoal and the taught command leads VelocityNet's; images recoloured to the taught light",
    ),
    "paper": Profile(
        ControllerConfig.paper,
        False,
        "the paper's Algorithm 1 exactly: raw image error, fixed threshold 17, the camera image as it is",
        "stop-and-go",
    ),
}


def _default(cls: type, name: str) -> Any:
    return cls.__dataclass_fields__[name].default


def _motion_default() -> str:
    return "the profile's (" + ", ".join(f"{n}: {p.motion}" for n, p in PROFILES.items()) + ")"


SAFETY = SafetyConfig()

#: Every setting, by table (docs/SETTINGS.md lists them in this order).
SETTINGS: tuple[Setting, ...] = (
    # [robot]: what describes the robot; every command reads it
    Setting(
        "robot",
        "address",
        str,
        "the robot's (or simulator's) ZeroMQ address, e.g. " + EXAMPLE,
        flag="--sim",
        metavar="ADDR",
        takes="tcp://HOST:PORT, ipc://PATH or inproc://NAME",
        check=check_endpoint,
        commands=("repeat", "teach", "check-robot"),
        goes="RepeatRunConfig.sim, TeachRunConfig.sim, check-robot's ADDR",
    ),
    Setting(
        "robot",
        "radius",
        float,
        "the robot's footprint: the radius of the circle that encloses it",
        SAFETY.radius,
        "m",
        low=0.0,
        high=5.0,
        low_open=True,
        flag="--robot-radius",
        metavar="M",
        commands=("repeat",),
        goes="RepeatRunConfig.repeat.safety.radius",
    ),
    # [repeat]
    Setting(
        "repeat",
        "model",
        str,
        "VelocityNet ONNX file (check-robot: the model whose cameras the image check compares with; without it, "
        "the camera the shipped model was trained at)",
        path=True,
        metavar="PATH",
        commands=("repeat", "check-robot"),
        goes="RepeatRunConfig.model, check-robot's image check",
    ),
    Setting(
        "repeat",
        "route",
        str,
        "taught route (.npz from `vtr teach`)",
        path=True,
        metavar="PATH",
        goes="RepeatRunConfig.route",
    ),
    Setting(
        "repeat",
        "profile",
        str,
        "the controller: default, or paper for the paper's Algorithm 1 exactly (docs/SETTINGS.md)",
        "default",
        choices=tuple(PROFILES),
        goes="RepeatRunConfig.repeat.controller (the profile's ControllerConfig), RepeatRunConfig.match_light",
    ),
    Setting(
        "repeat",
        "start",
        str,
        "route: reset the simulator to the route's start; here: the robot stands at "
        "the start; anywhere: it stands somewhere on the route, which is searched for where",
        "route",
        choices=("route", "here", "anywhere"),
        goes="RepeatRunConfig.start (a reset only for route), RepeatRunConfig.repeat.controller.localise (anywhere)",
    ),
    Setting(
        "repeat",
        "motion",
        str,
        "stop-and-go: a zero command after each control step (the paper's); "
        "continuous: keep moving between them; auto: continuous on a realtime robot, else stop-and-go",
        None,
        choices=("auto", "stop-and-go", "continuous"),
        default_text=_motion_default(),
        goes="RepeatRunConfig.motion",
    ),
    Setting(
        "repeat",
        "speed",
        float,
        "drive at this fraction of the taught pace and of the robot's speed limits (0.5: half speed)",
        _default(RepeatConfig, "speed"),
        "x",
        low=0.0,
        high=1.0,
        low_open=True,
        metavar="X",
        goes="RepeatRunConfig.repeat.speed",
    ),
    Setting(
        "repeat",
        "wait",
        float,
        "how long to wait for something in the way to clear before the run ends as blocked",
        _default(RepeatConfig, "wait_s"),
        "s",
        low=0.0,
        metavar="S",
        goes="RepeatRunConfig.repeat.wait_s",
    ),
    Setting(
        "repeat",
        "stop_distance",
        float,
        "stop when a range-scan point is this close ahead of the robot's edge",
        SAFETY.stop_distance,
        "m",
        low=0.0,
        high=10.0,
        metavar="M",
        goes="RepeatRunConfig.repeat.safety.stop_distance",
    ),
    Setting(
        "repeat",
        "slowdown_distance",
        float,
        f"slow to {SAFETY.slowdown_factor:g}x speed when a point is this close ahead (>= stop_distance)",
        SAFETY.slowdown_distance,
        "m",
        low=0.0,
        high=10.0,
        metavar="M",
        goes="RepeatRunConfig.repeat.safety.slowdown_distance",
    ),
    Setting(
        "repeat",
        "log",
        str,
        "write one JSON line per control step here, then the summary",
        None,
        path=True,
        metavar="PATH",
        goes="RepeatRunConfig.log",
    ),
    Setting(
        "repeat",
        "mcap",
        str,
        "also write the run as a ROS 2 bag for Foxglove and ros2 bag play (PATH.mcap: "
        "one file, else a folder); needs pip install 'vtr-mpc[ros]'",
        None,
        path=True,
        metavar="PATH",
        goes="RepeatRunConfig.mcap",
    ),
    Setting(
        "repeat",
        "foxglove",
        int,
        "serve the run live to Foxglove on ws://127.0.0.1:PORT (0: any free port); "
        "needs pip install 'vtr-mpc[foxglove]'",
        None,
        low=0,
        high=65535,
        metavar="PORT",
        goes="RepeatRunConfig.foxglove",
    ),
    Setting(
        "repeat", "json", bool, "print the summary as JSON instead of a line of text", False, goes="stdout"
    ),
    Setting(
        "repeat",
        "threads",
        int,
        "onnxruntime threads for the network (1 keeps the step's time steady on a busy board)",
        1,
        low=1,
        file_only=True,
        goes="RepeatRunConfig.threads",
    ),
    Setting(
        "repeat",
        "timeout",
        float,
        "how long to wait for a reply beyond the step's own duration; then a stop is sent",
        0.3,
        "s",
        low=0.0,
        low_open=True,
        metavar="S",
        goes="RepeatRunConfig.timeout_s",
    ),
    # [teach]
    Setting(
        "teach",
        "timeout",
        float,
        "how long to wait for hello and reset (a step waits its duration + 0.3 s)",
        5.0,
        "s",
        low=0.0,
        low_open=True,
        metavar="S",
        goes="TeachRunConfig.timeout_s",
    ),
    Setting(
        "teach",
        "retries",
        int,
        "tries per request before giving up",
        3,
        low=1,
        metavar="N",
        goes="TeachRunConfig.retries",
    ),
    # [check-robot]
    Setting(
        "check-robot",
        "timeout",
        float,
        "how long to wait for each reply",
        2.0,
        "s",
        low=0.0,
        low_open=True,
        metavar="S",
        goes="run_checks(timeout_s)",
    ),
    Setting(
        "check-robot",
        "budget",
        float,
        "time for the whole check",
        60.0,
        "s",
        low=0.0,
        low_open=True,
        metavar="S",
        goes="run_checks(budget_s)",
    ),
)

BY_NAME: dict[str, Setting] = {s.name: s for s in SETTINGS}


def for_command(command: str) -> tuple[Setting, ...]:
    """The settings ``command`` reads ("repeat", "teach", "check-robot"), in declaration order."""
    return tuple(s for s in SETTINGS if command in s.used_by)


def default(name: str) -> Any:
    """A setting's default, for the configs that keep one (one source: this table)."""
    return BY_NAME[name].default


def together(values: dict[str, Any], where: dict[str, str]) -> None:
    """Checks across settings (ValueError, one line): the stop zone lies inside the slowdown zone."""
    stop, slow = values.get("repeat.stop_distance"), values.get("repeat.slowdown_distance")
    if stop is not None and slow is not None and stop > slow:
        raise ValueError(
            f"stop_distance {stop:g} m ({where['repeat.stop_distance']}) is beyond slowdown_distance {slow:g} m "
            f"({where['repeat.slowdown_distance']}); allowed: stop_distance <= slowdown_distance"
        )
