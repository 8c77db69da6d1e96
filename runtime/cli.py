"""`vtr-robot`: the robot board's lean entry, with only its commands (teach, repeat, check-robot).

Dispatch, exit codes and the one-line errors are ``runtime.commands`` (shared with the full `vtr`).
``python -m vtr.runtime.cli`` is the same program (what a board without the console script runs).
"""

from __future__ import annotations

import sys

from vtr.runtime.commands import ROBOT_COMMANDS, dispatch


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    return dispatch("vtr-robot", "Visual teach & repeat on the robot board.", ROBOT_COMMANDS, argv)


if __name__ == "__main__":
    sys.exit(main())
