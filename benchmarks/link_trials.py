"""Timed link trials for `vtr bench link`: a robot that goes silent, a robot that reboots, mid-route, with
the real repeat loop (Repeater over SimClient) and a recording fake robot."""

from __future__ import annotations

import random
import threading
import time
from typing import Any

from vtr.benchmarks.link_robot import DrivingPolicy, FakeRobot, good_reply, unreachable_route
from vtr.runtime import protocol
from vtr.runtime.client import SimClient


def run_repeat(client: SimClient, stop_event: threading.Event | None = None, max_steps: int = 10_000) -> Any:
    """The real repeat loop with a policy that always drives, on a route it never reaches."""
    from vtr.runtime.controller import ControllerConfig
    from vtr.runtime.repeater import RepeatConfig, Repeater

    # no stall guard and no lost test: the route is unreachable on purpose, the trial is about the link
    cfg = RepeatConfig(
        controller=ControllerConfig(stall_steps=0, lost_steps=0), max_steps=max_steps, frame_timeout_s=2.0
    )
    return Repeater(client, DrivingPolicy(), unreachable_route(), config=cfg, stop_event=stop_event).run()


def silent(trials: int = 20, seed: int = 0) -> dict[str, Any]:
    """The robot stops answering after k steps; robot-side delay from that step to the first stop after it."""
    rng = random.Random(seed)
    delays, reasons = [], []
    for _ in range(trials):
        k = rng.randint(2, 8)

        def behaviour(robot: FakeRobot, req: protocol.Request, k: int = k) -> list[list[bytes]]:
            if req.cmd == "step" and len(robot.executed_steps) >= k:
                robot.mute = True  # from this step on it hears everything and answers nothing
            return [] if robot.mute else [good_reply(robot, req)]

        robot = FakeRobot(behaviour)
        with SimClient(robot.endpoint, expect_shape=(16, 16)) as client:
            summary = run_repeat(client)
        robot.close()
        cmds = robot.commands()
        last = max(i for i, a in enumerate(cmds) if a.req.cmd == "step")
        stop = next(a for a in cmds[last + 1 :] if a.req.cmd == "stop")
        delays.append(stop.t - cmds[last].t)
        reasons.append(summary.status.value)
    return _delay_summary(delays, trials, reasons, "step_to_zero_s")


def restart(trials: int = 20, seed: int = 0) -> dict[str, Any]:
    """The robot reboots (new session, same address) after k steps, mid-route."""
    rng = random.Random(seed)
    said, executed_after, steps_reaching = 0, 0, 0
    details = []
    for _ in range(trials):
        k = rng.randint(2, 8)
        robot = FakeRobot()
        with SimClient(robot.endpoint, expect_shape=(16, 16)) as client:
            timer = threading.Thread(target=_reboot_after, args=(robot, k), daemon=True)
            timer.start()
            summary = run_repeat(client)
            timer.join(5)
        robot.close()
        text = f"{summary.status.value}: {summary.detail}"
        said += int("restarted" in text)
        details.append(text.strip()[:120])
        new = robot.session
        executed_after += sum(1 for s, *_ in robot.executed_steps if s == new)
        steps_reaching += sum(1 for a in robot.commands() if a.session == new and a.req.cmd == "step")
    return {
        "trials": trials,
        "ended_saying_restarted": said,
        "steps_executed_by_rebooted_robot": executed_after,
        "steps_reaching_rebooted_robot_refused_by_session_guard": steps_reaching - executed_after,
        "examples": details[:3],
    }


def _reboot_after(robot: FakeRobot, k: int) -> None:
    deadline = time.monotonic() + 10
    while len(robot.executed_steps) < k and time.monotonic() < deadline:
        time.sleep(0.001)
    robot.restart()


def _delay_summary(delays: list[float], trials: int, reasons: list[str], name: str) -> dict[str, Any]:
    delays = sorted(delays)
    return {
        "trials": trials,
        f"{name}_p50": round(delays[len(delays) // 2], 3),
        f"{name}_p100": round(delays[-1], 3),
        f"{name}_all": [round(d, 3) for d in delays],
        "run_endings": sorted(set(reasons)),
    }
