"""`vtr`: the application's one entry point. It alone knows every package; the libraries export functions
and their own ``add_arguments``/``run_cli`` and never import a CLI of another package.

Dispatch, exit codes and the one-line errors are ``runtime.commands`` (shared with the robot board's lean
`vtr-robot`). ``python -m vtr.cli`` is the same program.
"""

from __future__ import annotations

import sys

from vtr.runtime.commands import ROBOT_COMMANDS, Command, dispatch

COMMANDS: dict[str, Command] = {
    "demo": Command(
        "vtr.evaluation.demo", "start the simulator, teach a route, repeat it with the shipped model", "sim"
    ),
    "sim": Command(
        "vtr.sim2d.cli",
        "simulator: serve over ZeroMQ, snapshot the house, generate routes",
        "sim",
        subcommands=True,
    ),
    **ROBOT_COMMANDS,
    # the robot's teach plus routes from ROS bags (a desktop job: rosbags, OpenCV)
    "teach": Command("vtr.teach_cmd", ROBOT_COMMANDS["teach"].summary + ", or make one from a ROS bag", None),
    "collect": Command(
        "vtr.training.collect",
        "record a training dataset: simulator, protocol robot (--sim) or ROS bags (--bag)",
        "sim",
    ),
    "train": Command(
        "vtr.pipeline",
        "train ViewNet, VelocityNet, or all (collect, train, export)",
        "train",
        subcommands=True,
    ),
    "export": Command("vtr.export.cli", "export a VelocityNet checkpoint to ONNX (fp32, int8)", "train"),
    "bench": Command(
        "vtr.benchmarks.cli",
        "latency per control step, simulator throughput, robot link faults",
        subcommands=True,
    ),
    "eval": Command("vtr.evaluation.harness", "closed-loop tracking against the paper's tables", "sim"),
}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    return dispatch("vtr", "Visual teach & repeat with an offline deep-MPC VelocityNet.", COMMANDS, argv)


if __name__ == "__main__":
    sys.exit(main())
