"""`vtr bench`: `latency` (per control step, per backend), `sim` (simulator throughput), `link` (faults), `pace` (realtime
repeat time against the taught time)."""

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
    "pace": Command(
        "vtr.benchmarks.realtime_pace",
        "repeat taught routes on a wall-clock robot: time against the teach's, steps against taught steps",
        "sim",
    ),
    "link": Command(
        "vtr.benchmarks.link_faults",
        "the robot link under fuzzed messages, silence, reboots and SIGKILL",
        "sim",
    ),
}
