"""`vtr bench link`: the robot link under faults, measured (issue 12's targets).

- ``server-fuzz``: N fuzzed requests to a live `vtr sim serve` process: deaths, replies, RSS growth.
- ``client-fuzz``: N fuzzed replies to the client: tracebacks, desyncs that outlive one bad reply.
- ``loop-fuzz``: N fuzzed replies to the repeat loop: tracebacks, motion commands sent right after a bad one.
- ``silent``: the robot goes silent mid-route; robot-side delay from the unanswered step to the zero command.
- ``restart``: the robot reboots mid-route; how the repeat ends, motion executed by the rebooted robot.
- ``sigkill``: `vtr repeat --motion continuous` on a realtime simulator is killed; delay until the robot is at rest.
- ``files``: crafted routes, datasets and models: code run, peak memory against the file's size.

Each prints one JSON object (and writes it with ``--out``). Faults come from a seeded generator.
"""

from __future__ import annotations

import argparse
import json
import random
import time
from typing import Any

import zmq

from vtr.benchmarks.link_fuzz import HARMLESS, FaultInjector, fuzz_request
from vtr.benchmarks.link_robot import FakeRobot
from vtr.benchmarks.link_trials import restart, run_repeat, silent
from vtr.runtime import protocol
from vtr.runtime.client import SimClient
from vtr.runtime.protocol import ProtocolError
from vtr.runtime.robot import RobotError


def rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


# ------------------------------------------------------------------------------------------- server fuzz


def server_fuzz(n: int = 10_000, seed: int = 0, warmup: int = 500) -> dict[str, Any]:
    """Send ``n`` fuzzed requests to a server process; a death is a request after which it is gone."""
    from vtr.sim2d.server import ServerConfig, start_server_process

    rng = random.Random(seed)
    cfg = ServerConfig(bind="tcp://127.0.0.1:*", poll_ms=20)
    handle = start_server_process(cfg)
    ctx = zmq.Context()
    deaths = replies = well_formed = cut_off = lost = 0
    rss0 = None

    def fresh() -> zmq.Socket:
        s = ctx.socket(zmq.REQ)
        s.setsockopt(zmq.LINGER, 0)
        s.connect(handle.endpoint)
        return s

    sock = fresh()
    t0 = time.perf_counter()
    for i in range(n):
        if i == warmup:
            rss0 = rss_mb(handle.process.pid)
        frames, dropped = fuzz_request(rng, i)
        if dropped:  # ZeroMQ cuts this peer off; send from a throwaway socket
            tmp = ctx.socket(zmq.DEALER)
            tmp.setsockopt(zmq.LINGER, 0)
            tmp.connect(handle.endpoint)
            tmp.send_multipart([b"", *frames])
            cut_off += int(not tmp.poll(300))
            tmp.close()
            continue
        sock.send_multipart(frames)
        if sock.poll(10_000):
            replies += 1
            try:
                protocol.decode_reply(sock.recv_multipart())
                well_formed += 1
            except ProtocolError:
                pass
            continue
        sock.close()
        if not handle.process.is_alive():
            deaths += 1
            handle = start_server_process(cfg)
        else:
            lost += 1
        sock = fresh()
    seconds = time.perf_counter() - t0
    rss1 = rss_mb(handle.process.pid)
    sock.close()
    ctx.term()
    handle.terminate()
    return {
        "requests": n,
        "seed": seed,
        "server_deaths": deaths,
        "replies": replies,
        "well_formed_replies": well_formed,
        "cut_off_by_maxmsgsize": cut_off,
        "unanswered_while_alive": lost,
        "rss_after_warmup_mb": round(rss0 or 0.0, 1),
        "rss_end_mb": round(rss1, 1),
        "rss_growth_mb": round(rss1 - (rss0 or rss1), 1),
        "seconds": round(seconds, 1),
    }


# ------------------------------------------------------------------------------------------- client fuzz


def client_fuzz(n: int = 2000, seed: int = 0, p_fault: float = 0.5) -> dict[str, Any]:
    """Drive a client through observe/step/stop while the robot answers with ``n`` faulty replies in all.

    An exchange is *clean* when every request in it got only the correct reply (and no late reply was
    pending); a clean exchange the client fails, or one that returns anything but that reply, is a desync.
    """
    inject = FaultInjector(random.Random(seed), n, p_fault, harmless=("duplicate", "stale_then_good"))

    def behaviour(robot: FakeRobot, req: protocol.Request) -> list[list[bytes]]:
        robot.pose_x = float(req.seq)  # a pose that names the request it answers
        return inject(robot, req)

    robot = FakeRobot(behaviour)
    tracebacks: list[str] = []
    desyncs = exchanges = clean = 0
    desync_examples: list[str] = []
    calls = ("observe", "step", "stop")
    with SimClient(robot.endpoint, timeout_s=0.05, retries=2, expect_shape=(16, 16)) as client:
        t0 = time.perf_counter()
        while len(inject.faults) < n:
            call = calls[exchanges % 3]
            inject.dirty = False
            result: Any = None
            failure = ""
            try:
                if call == "observe":
                    result = client.observe()
                elif call == "step":
                    result = client.step(0.2, 0.1, 0.1)
                else:
                    client.stop()
                    result = "stopped"
            except (ProtocolError, RobotError) as exc:
                result, failure = None, f"{type(exc).__name__}: {exc}"
            except Exception as exc:  # a traceback in a real run
                tracebacks.append(f"{type(exc).__name__}: {exc}")
            exchanges += 1
            if not inject.dirty:
                clean += 1
                ok = result == "stopped" or (result is not None and result.pose[0] == client._seq)
                if not ok:
                    desyncs += 1
                    seen = failure or getattr(result, "pose", result)
                    desync_examples.append(f"{call} seq {client._seq}: {seen}"[:200])
        seconds = time.perf_counter() - t0
        counters = {
            "bad_frames": client.bad_frames,
            "stale_replies": client.stale_replies,
            "timeouts": client.timeouts,
        }
    robot.close()
    return {
        "fuzzed_replies": len(inject.faults),
        "fault_kinds": inject.kinds(),
        "exchanges": exchanges,
        "clean_exchanges": clean,
        "desyncs": desyncs,
        "desync_examples": desync_examples[:3],
        "client_tracebacks": len(tracebacks),
        "traceback_examples": tracebacks[:3],
        "client_counters": counters,
        "seed": seed,
        "seconds": round(seconds, 1),
    }


# ------------------------------------------------------------------------------------------- the repeat loop


def loop_fuzz(n: int = 2000, seed: int = 0, p_fault: float = 0.3) -> dict[str, Any]:
    """The repeat loop (Repeater over SimClient) while the robot sends ``n`` faulty replies in all: what is
    the next request after each fault? A step there is a motion command sent on a bad frame."""
    inject = FaultInjector(random.Random(seed), n, p_fault, harmless=HARMLESS)
    faults = inject.faults

    robot = FakeRobot(inject)
    tracebacks: list[str] = []
    endings: dict[str, int] = {}
    run_starts: set[int] = set()  # the first request of each run: what follows a run's end is not a reaction
    t0 = time.perf_counter()
    while len(faults) < n:
        run_starts.add(len(robot.arrivals))
        with SimClient(robot.endpoint, timeout_s=0.05, retries=2, expect_shape=(16, 16)) as client:
            try:
                summary = run_repeat(client, max_steps=200)
                endings[summary.status.value] = endings.get(summary.status.value, 0) + 1
            except Exception as exc:  # escaped the loop: a traceback in a real run
                tracebacks.append(f"{type(exc).__name__}: {exc}")
    seconds = time.perf_counter() - t0
    robot.close()
    arrivals = robot.arrivals
    after: dict[str, int] = {}
    motion_after_bad = 0
    unusual: list[str] = []
    for index, kind in faults:
        if kind in HARMLESS or index + 1 >= len(arrivals) or index + 1 in run_starts:
            continue
        nxt = arrivals[index + 1].req
        name = nxt.cmd if nxt is not None else "undecodable"
        after[name] = after.get(name, 0) + 1
        if name != "stop":
            faulty = arrivals[index].req
            unusual.append(f"{kind} reply to {faulty.cmd if faulty else '?'} -> next {name}")
        if nxt is not None and nxt.cmd == "step" and (nxt.fields["v"] or nxt.fields["w"]):
            motion_after_bad += 1
    return {
        "fuzzed_replies": len(faults),
        "harmless_faults": sum(1 for _, k in faults if k in HARMLESS),
        "next_request_after_a_bad_reply": after,
        "nonzero_commands_after_a_bad_frame": motion_after_bad,
        "not_followed_by_a_stop": sorted(set(unusual))[:12],
        "loop_tracebacks": len(tracebacks),
        "traceback_examples": tracebacks[:3],
        "run_endings": endings,
        "seed": seed,
        "seconds": round(seconds, 1),
    }


# ------------------------------------------------------------------------------------------- CLI

BENCHES = ("server-fuzz", "client-fuzz", "loop-fuzz", "silent", "restart", "sigkill", "files")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("which", choices=(*BENCHES, "all"), help="which fault benchmark to run")
    parser.add_argument("--n", type=int, default=None, help="fuzzed messages (default: 10000 / 2000)")
    parser.add_argument(
        "--trials", type=int, default=20, help="trials for silent/restart/sigkill (default: 20)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the fault generator (default: 0)")
    parser.add_argument(
        "--cmd-vel-timeout",
        type=float,
        default=0.5,
        help="sigkill: the simulator's watchdog; 0 runs the control without it (default: 0.5)",
    )
    parser.add_argument("--out", default=None, help="also write the JSON result here")


def run_cli(args: argparse.Namespace) -> int:
    from vtr.benchmarks.link_files import files
    from vtr.benchmarks.link_sigkill import sigkill
    from vtr.runtime.atomic import write_text_atomic

    runs = {
        "server-fuzz": lambda: server_fuzz(args.n or 10_000, args.seed),
        "client-fuzz": lambda: client_fuzz(args.n or 2000, args.seed),
        "loop-fuzz": lambda: loop_fuzz(args.n or 2000, args.seed),
        "silent": lambda: silent(args.trials, args.seed),
        "restart": lambda: restart(args.trials, args.seed),
        "sigkill": lambda: sigkill(args.trials, args.seed, cmd_vel_timeout=args.cmd_vel_timeout),
        "files": files,
    }
    result: dict[str, Any] = {}
    for name in BENCHES if args.which == "all" else (args.which,):
        print(f"vtr bench link: {name} ...", flush=True)
        result[name] = runs[name]()
        print(json.dumps({name: result[name]}), flush=True)
    if args.out:
        write_text_atomic(args.out, json.dumps(result, indent=2) + "\n")
    return 0
