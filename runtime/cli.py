"""Command dispatch shared by the entry points, and the robot board's lean entry, `vtr-robot`.

Each command lives in its own module exposing ``add_arguments(parser)`` and ``run_cli(args) -> int``,
imported by name only when it runs, so `vtr-robot repeat` never imports torch or pymunk and `--help`
works with no extras installed. The full `vtr` command (``vtr/cli.py``, the application layer) uses the
same :func:`dispatch` with every package's commands.

Exit codes, the same for every command: 0 success, 1 a run that failed (a repeat that stalled, a demo
that did not finish), 2 a usage or input error (one line on stderr naming the problem and the fix),
130 an interrupt.
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
    extra: str | None  # the pip extra that provides its heavy dependencies


#: The robot board's commands: numpy, onnxruntime and pyzmq only.
ROBOT_COMMANDS: dict[str, Command] = {
    "teach": Command("vtr.runtime.teach", "drive a scripted route and record its visual trajectory", None),
    "repeat": Command(
        "vtr.runtime.daemon", "follow a taught route from camera images alone (the robot daemon)", None
    ),
    "check-robot": Command(
        "vtr.runtime.check_robot", "check that a robot bridge speaks the protocol correctly", None
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


def _missing_extra(prog: str, command: Command, err: ModuleNotFoundError) -> str:
    missing = (err.name or "").split(".")[0]
    extra = EXTRA_OF_MODULE.get(missing, command.extra)
    hint = f"; install it with: pip install 'vtr-mpc[{extra}]'" if extra else ""
    return f"{prog}: needs the Python package '{missing}', which is not installed{hint}"


def dispatch(prog: str, description: str, commands: Mapping[str, Command], argv: list[str]) -> int:
    """Run ``argv[0]`` of ``commands`` with the rest of ``argv``; returns the exit code."""
    if not argv or argv[0] in ("-h", "--help"):
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
        parser = OneLineParser(prog=where, description=command.summary)
        module.add_arguments(parser)
        args = parser.parse_args(argv)
        return int(module.run_cli(args) or 0)
    except ModuleNotFoundError as err:
        if err.name and err.name.split(".")[0] in EXTRA_OF_MODULE:
            print(_missing_extra(where, command, err), file=sys.stderr)
            return EXIT_USAGE
        raise
    except KeyboardInterrupt:
        print(f"{where}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (ValueError, OSError) as err:  # bad input the command did not word itself: still one line
        text = " ".join(str(err).split()) or type(err).__name__
        print(f"{where}: {text}", file=sys.stderr)
        return EXIT_USAGE


def main(argv: list[str] | None = None) -> int:
    """`vtr-robot`: the robot board's commands only."""
    argv = list(sys.argv[1:] if argv is None else argv)
    return dispatch("vtr-robot", "Visual teach & repeat on the robot board.", ROBOT_COMMANDS, argv)


if __name__ == "__main__":
    sys.exit(main())
