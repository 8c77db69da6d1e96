"""`vtr bench`: `latency` (per control step, per backend), `sim` (simulator throughput), `link` (faults)."""

from __future__ import annotations

from vtr.runtime.commands import Command

# modules load only when their subcommand runs
COMMANDS = {
    "latency": Command(
        "vtr.benchmarks.latency", "CPU latency of one control step, stage by stage and backend by backend"
    ),
    "sim": Command(
        "vtr.benchmarks.sim_throughput", "simulator steps per second (in-process and over ZeroMQ)", "sim"
    ),
    "link": Command(
        "vtr.benchmarks.link_faults",
        "the robot link under fuzzed messages, silence, reboots and SIGKILL",
        "sim",
    ),
}
