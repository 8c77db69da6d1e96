"""The training stages as a program of their own, for torchrun (which needs a module to launch):

    torchrun --nproc_per_node=4 -m vtr.training.app viewnet --preset paper --data data/house.npz --out runs/paper/viewnet

Same options and exit codes as `vtr train viewnet|velocitynet`, without the robot board's package.
"""

from __future__ import annotations

import sys

from vtr.runtime.commands import Command, run_command

STAGES = Command("vtr.training.cli", "train ViewNet or VelocityNet", "train", subcommands=True)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    return run_command("python -m vtr.training.app", STAGES, argv)


if __name__ == "__main__":
    sys.exit(main())
