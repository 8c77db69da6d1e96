"""The `vtr` command: one entry point, one module per subcommand.

Each subcommand lives in its own module exposing ``add_arguments(parser)`` and ``run_cli(args) -> int``.
Modules are imported by name only when their subcommand runs, so ``vtr repeat`` on a robot board never
imports torch or pymunk, and ``vtr --help`` works with no extras installed.
"""

from __future__ import annotations

import argparse
import importlib
import sys

# name -> (module, one-line summary, extra that provides its heavy dependencies)
COMMANDS: dict[str, tuple[str, str, str | None]] = {
    "demo": (
        "vtr.benchmarks.demo",
        "start the simulator, teach a route, repeat it with the shipped model",
        "sim",
    ),
    "sim": ("vtr.sim2d.cli", "simulator: serve over ZeroMQ, snapshot the house", "sim"),
    "teach": ("vtr.runtime.teach", "drive a scripted route and record its visual trajectory", None),
    "repeat": (
        "vtr.runtime.daemon",
        "follow a taught route from camera images alone (the robot daemon)",
        None,
    ),
    "check-robot": (
        "vtr.runtime.check_robot",
        "check that a robot bridge speaks the protocol correctly",
        None,
    ),
    "collect": ("vtr.training.collect", "drive the simulated robot and record a training dataset", "sim"),
    "train": ("vtr.training.cli", "train ViewNet, then VelocityNet with the offline MPC loss", "train"),
    "export": ("vtr.export.cli", "export a VelocityNet checkpoint to ONNX (fp32, int8)", "train"),
    "bench": ("vtr.benchmarks.cli", "latency per control step, simulator throughput", None),
    "eval": ("vtr.benchmarks.evaluate", "closed-loop tracking against the paper's tables", "sim"),
}

_EXTRA_OF_MODULE = {
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


def _top_help() -> str:
    width = max(len(n) for n in COMMANDS)
    lines = [
        "usage: vtr COMMAND [options]",
        "",
        "Visual teach & repeat with an offline deep-MPC VelocityNet.",
        "",
        "commands:",
    ]
    lines += [f"  {name:<{width}}  {summary}" for name, (_, summary, _) in COMMANDS.items()]
    lines += ["", "Run `vtr COMMAND --help` for a command's options."]
    return "\n".join(lines)


def _missing_extra_message(command: str, err: ModuleNotFoundError) -> str:
    missing = (err.name or "").split(".")[0]
    extra = _EXTRA_OF_MODULE.get(missing, COMMANDS[command][2])
    hint = f" Install it with: pip install 'vtr-mpc[{extra}]'" if extra else ""
    return f"vtr {command}: needs the Python package '{missing}', which is not installed.{hint}"


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(_top_help())
        return 0
    if argv[0] == "--version":
        from vtr.runtime import __version__

        print(__version__)
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"vtr: unknown command {name!r}\n\n{_top_help()}", file=sys.stderr)
        return 2
    module_name, summary, _ = COMMANDS[name]
    try:
        module = importlib.import_module(module_name)
        parser = argparse.ArgumentParser(prog=f"vtr {name}", description=summary)
        module.add_arguments(parser)
        args = parser.parse_args(rest)
        return int(module.run_cli(args) or 0)
    except ModuleNotFoundError as err:
        if err.name and err.name.split(".")[0] in _EXTRA_OF_MODULE:
            print(_missing_extra_message(name, err), file=sys.stderr)
            return 3
        raise
    except KeyboardInterrupt:
        print(f"vtr {name}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
