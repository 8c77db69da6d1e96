"""`vtr bench`: `latency` (per control step, per backend), `sim` (simulator throughput), `link` (faults)."""

from __future__ import annotations

import argparse
import importlib

from vtr.runtime.cliargs import OneLineParser

# subcommand -> (module, summary); modules load only when their subcommand runs
SUBCOMMANDS = {
    "latency": (
        "vtr.benchmarks.latency",
        "CPU latency of one control step, stage by stage and backend by backend",
    ),
    "sim": ("vtr.benchmarks.sim_throughput", "simulator steps per second (in-process and over ZeroMQ)"),
    "link": (
        "vtr.benchmarks.link_faults",
        "the robot link under fuzzed messages, silence, reboots and SIGKILL",
    ),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("subcommand", choices=sorted(SUBCOMMANDS), help="which benchmark to run")
    parser.add_argument("rest", nargs=argparse.REMAINDER, help="options of the benchmark (see its --help)")


def run_cli(args: argparse.Namespace) -> int:
    module_name, summary = SUBCOMMANDS[args.subcommand]
    module = importlib.import_module(module_name)
    sub = OneLineParser(prog=f"vtr bench {args.subcommand}", description=summary)
    module.add_arguments(sub)
    return int(module.run_cli(sub.parse_args(args.rest)) or 0)
