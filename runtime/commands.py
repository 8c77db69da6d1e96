"""The one way a command line dispatches: a table of name -> :class:`Command`, run by :func:`dispatch`.

A command names the module that holds it, imported by name only when the command runs (so `vtr-robot
repeat` never imports torch or pymunk and `--help` works with no extras installed), and two functions of
that module: ``add_arguments(parser)`` declares its options and ``run_cli(args) -> int`` runs them. A
command with subcommands (``subcommands=True``) names a module whose ``COMMANDS`` table is dispatched the
same way with the rest of the command line (`vtr sim serve`, `vtr train velocitynet`, `vtr bench latency`).
Every entry point uses this: `vtr` (``vtr/cli.py``), `vtr-robot` (``runtime/cli.py``) and the torchrun
programs (``training/app.py``, ``vtr/pipeline.py``).

Exit codes, the same for every command: 0 success, 1 a run that failed (a repeat that stalled, a demo
that did not finish), 2 a usage or input error (one line on stderr naming the problem and the fix; a
missing command prints the command list on stderr), 130 an interrupt.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Mapping
from typing import NamedTuple

from vtr.runtime.cliargs import OneLineParser

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


class Command(NamedTuple):
    module: str  # imported when the command runs
    summary: str  # one line for the command list
    extra: str | None = None  # the pip extra that provides its heavy dependencies
    add: str = "add_arguments"  # the module's function that declares the options on a parser
    run: str = "run_cli"  # the module's function that runs the parsed options -> exit code
    subcommands: bool = False  # the module's COMMANDS table holds the subcommands instead


#: The robot board's commands: numpy, onnxruntime and pyzmq only (`vtr-robot`; `vtr` has them too).
ROBOT_COMMANDS: dict[str, Command] = {
    "teach": Command(
        "vtr.runtime.teach", "drive a route (scripted, by keyboard or by its joystick) and record what it saw"
    ),
    "repeat": Command(
        "vtr.runtime.daemon", "follow a taught route from camera images alone (the robot daemon)"
    ),
    "check-robot": Command(
        "vtr.runtime.check_robot", "check that a robot bridge speaks the protocol correctly"
    ),
}

#: Third-party module -> the extra that installs it (for the "not installed" message).
EXTRA_OF_MODULE = {
    "pymunk": "sim",
    "cv2": "sim",
    "matplotlib": "sim",
    "torch": "train",
    "onnx": "train",
    "onnxscript": "train",
    "tqdm": "train",
    "gymnasium": "dev",
    "rosbags": "ros",
    "foxglove": "foxglove",
}


def help_text(prog: str, description: str, commands: Mapping[str, Command]) -> str:
    width = max(len(n) for n in commands)
    lines = [f"usage: {prog} COMMAND [options]", "", description, "", "commands:"]
    lines += [f"  {name:<{width}}  {c.summary}" for name, c in commands.items()]
    lines += ["", f"Run `{prog} COMMAND --help` for a command's options."]
    return "\n".join(lines)


def missing_extra(prog: str, command: Command, err: ModuleNotFoundError) -> str:
    missing = (err.name or "").split(".")[0]
    extra = EXTRA_OF_MODULE.get(missing, command.extra)
    hint = f"; install it with: pip install 'vtr-mpc[{extra}]'" if extra else ""
    return f"{prog}: needs the Python package '{missing}', which is not installed{hint}"


def dispatch(prog: str, description: str, commands: Mapping[str, Command], argv: list[str]) -> int:
    """Run ``argv[0]`` of ``commands`` with the rest of ``argv``; returns the exit code."""
    if not argv:  # no command: the list, as a usage error
        print(help_text(prog, description, commands), file=sys.stderr)
        return EXIT_USAGE
    if argv[0] in ("-h", "--help"):
        print(help_text(prog, description, commands))
        return EXIT_OK
    if argv[0] == "--version":
        from vtr import __version__

        print(__version__)
        return EXIT_OK
    name, rest = argv[0], argv[1:]
    if name not in commands:
        print(f"{prog}: unknown command {name!r}; choose one of {', '.join(commands)}", file=sys.stderr)
        return EXIT_USAGE
    return run_command(f"{prog} {name}", commands[name], rest)


def run_command(where: str, command: Command, argv: list[str]) -> int:
    """Parse ``argv`` for ``command`` and run it, turning errors into exit codes (see the module docstring)."""
    try:
        module = importlib.import_module(command.module)
        if command.subcommands:
            return dispatch(where, command.summary, module.COMMANDS, argv)
        parser = OneLineParser(prog=where, description=command.summary)
        getattr(module, command.add)(parser)
        args = parser.parse_args(argv)
        return int(getattr(module, command.run)(args) or 0)
    except ModuleNotFoundError as err:
        if err.name and err.name.split(".")[0] in EXTRA_OF_MODULE:
            print(missing_extra(where, command, err), file=sys.stderr)
            return EXIT_USAGE
        raise
    except KeyboardInterrupt:
        print(f"{where}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (ValueError, OSError) as err:  # bad input the command did not word itself: still one line
        text = " ".join(str(err).split()) or type(err).__name__
        print(f"{where}: {text}", file=sys.stderr)
        return EXIT_USAGE
