"""`vtr check-robot ADDR`: a conformance checker for a robot bridge (or simulator) speaking runtime/protocol.py.

In the spirit of gymnasium's env_checker: small named checks, each one line (PASS / WARN / FAIL / SKIP and what
to fix), a summary, exit status 1 when anything failed. It talks raw ZeroMQ so that it can send requests the
runtime's client would never send (malformed, beyond the limits). Every request has a timeout, a timed-out socket
is rebuilt, and the whole run has a time budget: it never hangs.

The robot moves: a zero step, a turn in place of about 0.3 rad and back, and steps the robot must refuse. It ends
with a ``stop``. Run it with the robot in free space.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import zmq

from vtr.runtime import protocol
from vtr.runtime.check_link import CheckFailed, Link, image_diff, percentile_ms
from vtr.runtime.contracts import CONTROL_DT
from vtr.runtime.hello import Hello, parse_hello

PASS, WARN, FAIL, SKIP = "PASS", "WARN", "FAIL", "SKIP"
#: Image size the shipped model takes.
MODEL_IMAGE_SIZE = (128, 128)
#: A turn this large must change the view (radians).
TURN_ANGLE = 0.3


@dataclass
class CheckResult:
    name: str
    status: str
    detail: str


@dataclass
class Context:
    """What the checks learn from the robot, shared between them in order."""

    link: Link
    hello: Hello | None = None
    camera: tuple[int, int] | None = None  # (height, width) announced
    limits: protocol.Limits | None = None
    dt: float = CONTROL_DT  # step duration used by the checks
    resets: bool = False
    image: np.ndarray | None = None  # the last image seen
    noise_floor: float = 0.0  # mean abs difference between two frames of a robot at rest
    stamps: list[tuple[str, float]] = field(default_factory=list)  # (cmd, stamp) since the last reset
    stamp_problems: list[str] = field(default_factory=list)

    def note_stamp(self, reply: protocol.Reply) -> None:
        if reply.stamp is None:
            return
        if reply.cmd == "reset":
            self.stamps.clear()
        elif self.stamps:
            cmd0, before = self.stamps[-1]
            if reply.stamp < before:
                self.stamp_problems.append(f"{reply.cmd!r} stamp {reply.stamp} < previous {cmd0!r} {before}")
            elif reply.cmd == "step" and reply.stamp <= before:
                self.stamp_problems.append(f"a step did not advance the stamp ({before} -> {reply.stamp})")
        self.stamps.append((str(reply.cmd), reply.stamp))

    def ask(self, cmd: str, **fields: Any) -> protocol.Reply:
        """A well-formed request whose ok reply must decode; CheckFailed otherwise."""
        reply = self.link.ask(cmd, **fields)
        if not reply.ok:
            raise CheckFailed(f"{cmd!r} was refused: {reply.error}")
        self.note_stamp(reply)
        if reply.image is not None:
            self._check_shape(reply.image)
            self.image = reply.image
        return reply

    def _check_shape(self, image: np.ndarray) -> None:
        if self.camera is not None and image.shape[:2] != self.camera:
            raise CheckFailed(
                f"image is {image.shape[0]}x{image.shape[1]} but hello announced {self.camera[0]}x{self.camera[1]}"
            )

    def step(self, v: float, w: float) -> protocol.Reply:
        return self.ask("step", v=v, w=w, duration=self.dt)


Check = Callable[[Context], tuple[str, str]]


def check_hello(ctx: Context) -> tuple[str, str]:
    reply = ctx.link.ask("hello")
    if not reply.ok:
        raise CheckFailed(f"hello was refused: {reply.error}; hello must always succeed")
    ctx.note_stamp(reply)
    try:
        ctx.hello = parse_hello(reply)
    except protocol.BadFrameError as exc:
        raise CheckFailed(f"hello: {exc} (docs/PROTOCOL.md, 'hello', lists what to announce)") from None
    hello = ctx.hello
    ctx.camera, ctx.limits = (hello.camera.height, hello.camera.width), hello.limits
    ctx.dt = min(max(CONTROL_DT, hello.dt), hello.limits.max_duration)
    lim = hello.limits
    return PASS, (
        f"session {hello.session}; limits v_max {lim.v_max} m/s, w_max {lim.w_max} rad/s, "
        f"max_duration {lim.max_duration} s"
    )


def check_hello_camera(ctx: Context) -> tuple[str, str]:
    assert ctx.hello is not None
    cam = ctx.hello.camera
    text = f"{cam.width}x{cam.height}"
    missing = [k for k in ("fov_deg", "height_m") if getattr(cam, k) is None]
    if missing:
        return (
            WARN,
            f"{text}; announce camera.{' and camera.'.join(missing)} so the runtime can compare the camera",
        )
    return PASS, f"{text}, fov {cam.fov_deg} deg, height {cam.height_m} m"


def check_hello_clock(ctx: Context) -> tuple[str, str]:
    assert ctx.hello is not None
    h = ctx.hello
    text = f"mode {h.mode}, dt {h.dt} s"
    if h.mode == "realtime":
        if not h.cmd_vel_timeout:
            return (
                WARN,
                f"{text}: announce and enforce cmd_vel_timeout (0.5 s) so a lost client leaves the robot at rest",
            )
        text += f", cmd_vel_timeout {h.cmd_vel_timeout} s"
    return PASS, text


def check_reset(ctx: Context) -> tuple[str, str]:
    reply = ctx.link.ask("reset")
    if not reply.ok:
        return WARN, (
            f"reset refused ({reply.error}): fine for a real robot, but `vtr teach` needs it and "
            "`vtr collect --sim` will drive continuously"
        )
    ctx.note_stamp(reply)
    assert reply.image is not None
    ctx._check_shape(reply.image)
    ctx.image, ctx.resets = reply.image, True
    return PASS, f"image {reply.image.shape[1]}x{reply.image.shape[0]}, stamp {reply.stamp}"


def check_observe(ctx: Context) -> tuple[str, str]:
    first = ctx.ask("observe")
    second = ctx.ask("observe")
    assert first.image is not None and second.image is not None
    ctx.noise_floor = image_diff(first.image, second.image)
    if ctx.noise_floor > 10:
        return WARN, f"two frames of a robot at rest differ by {ctx.noise_floor:.1f}/255: is it still moving?"
    return PASS, f"rgb8 {first.image.shape[1]}x{first.image.shape[0]}, rest noise {ctx.noise_floor:.2f}/255"


def check_image(ctx: Context) -> tuple[str, str]:
    image = ctx.image
    if image is None:
        raise CheckFailed("no image seen yet")
    if float(image.std()) == 0.0:
        return WARN, "the image is one flat colour: is the camera covered or not streaming?"
    if image.shape[:2] != MODEL_IMAGE_SIZE:
        return WARN, (
            f"{image.shape[1]}x{image.shape[0]}: the shipped model takes 128x128; resize in the bridge "
            "or train a model for this size"
        )
    return PASS, f"{image.shape[1]}x{image.shape[0]} rgb8, mean {image.mean():.0f}, std {image.std():.0f}"


def check_stop(ctx: Context) -> tuple[str, str]:
    reply = ctx.ask("stop")
    return PASS, f"stamp {reply.stamp}"


def check_zero_step(ctx: Context) -> tuple[str, str]:
    before = ctx.ask("observe")
    after = ctx.step(0.0, 0.0)
    assert before.image is not None and after.image is not None
    diff = image_diff(before.image, after.image)
    tolerance = max(2.0, 2 * ctx.noise_floor + 1)
    if diff > tolerance:
        raise CheckFailed(
            f"a zero step changed the image by {diff:.1f}/255 (> {tolerance:.1f}): the robot moved"
        )
    assert before.stamp is not None and after.stamp is not None
    advance = after.stamp - before.stamp
    if not 0.5 * ctx.dt <= advance <= 3 * ctx.dt + 0.5:
        return WARN, f"a step of {ctx.dt} s advanced the stamp by {advance:.3f} s"
    return PASS, f"image change {diff:.2f}/255, stamp +{advance:.3f} s"


def check_turn(ctx: Context) -> tuple[str, str]:
    assert ctx.limits is not None
    w = 0.5 * ctx.limits.w_max
    n = max(1, min(20, math.ceil(TURN_ANGLE / (w * ctx.dt))))
    start = ctx.ask("observe")
    assert start.image is not None
    turned = start
    try:
        for _ in range(n):
            turned = ctx.step(0.0, w)
    finally:
        ctx.link.ask("stop")
    assert turned.image is not None
    diff = image_diff(start.image, turned.image)
    problems = []
    if diff <= max(4.0, 3 * ctx.noise_floor + 2):
        problems.append(f"turning {n * w * ctx.dt:.2f} rad in place changed the image by only {diff:.1f}/255")
    if start.pose is not None and turned.pose is not None:
        dyaw = (turned.pose[2] - start.pose[2] + math.pi) % (2 * math.pi) - math.pi
        if dyaw <= 0:
            problems.append(
                f"w > 0 moved pose.yaw by {dyaw:+.3f} rad: w is counter-clockwise positive (REP-103)"
            )
    back = turned
    try:
        for _ in range(n):
            back = ctx.step(0.0, -w)
    finally:
        ctx.link.ask("stop")
    if problems:
        raise CheckFailed("; ".join(problems))
    assert back.image is not None
    undo = image_diff(start.image, back.image)
    note = f"turn changed the image by {diff:.1f}/255, turning back left {undo:.1f}/255"
    if turned.collided or back.collided:
        return WARN, note + "; 'collided' was true during a turn in place"
    return PASS, note


def check_stamps(ctx: Context) -> tuple[str, str]:
    if ctx.stamp_problems:
        raise CheckFailed("; ".join(ctx.stamp_problems[:3]) + ": stamps never go back within a session")
    return PASS, f"{len(ctx.stamps)} replies since the last reset, stamps never decreased"


def _refused(ctx: Context, what: str, **fields: Any) -> str:
    """Send a step the robot must refuse; return the error text."""
    try:
        reply = ctx.link.ask("step", **fields)
    finally:
        ctx.link.ask("stop")
    if reply.ok:
        raise CheckFailed(f"a step with {what} was accepted: reject it with an error reply naming the limit")
    return str(reply.error)


def check_limits_enforced(ctx: Context) -> tuple[str, str]:
    assert ctx.limits is not None
    lim, dt = ctx.limits, ctx.dt
    _refused(ctx, f"v={1.5 * lim.v_max} m/s (v_max {lim.v_max})", v=1.5 * lim.v_max, w=0.0, duration=dt)
    _refused(ctx, f"w={-1.5 * lim.w_max} rad/s (w_max {lim.w_max})", v=0.0, w=-1.5 * lim.w_max, duration=dt)
    _refused(ctx, "duration=0", v=0.0, w=0.0, duration=0.0)
    error = _refused(ctx, f"duration={2 * lim.max_duration} s", v=0.0, w=0.0, duration=2 * lim.max_duration)
    try:  # a step exactly at the limit must still be served (turn in place at w_max, and back)
        ctx.step(0.0, lim.w_max)
        ctx.step(0.0, -lim.w_max)
    finally:
        ctx.link.ask("stop")
    return PASS, f"4 out-of-range steps refused (e.g. {error!r}); a step at w_max served"


BAD_REQUESTS: list[tuple[str, list[bytes], bool]] = [
    # (what, frames, whether cmd and seq are readable and must be echoed)
    ("malformed JSON", [b'{"proto": "vtr-sim", "version": 1, "cmd": '], False),
    ("header not an object", [b"[1, 2, 3]"], False),
    ("wrong protocol name", [b'{"proto": "ros", "version": 1, "cmd": "observe", "seq": 901, "stamp": 0}'], True),
    ("unknown version", [b'{"proto": "vtr-sim", "version": 99, "cmd": "observe", "seq": 902, "stamp": 0}'], True),
    ("unknown command", [b'{"proto": "vtr-sim", "version": 1, "cmd": "fly", "seq": 903, "stamp": 0}'], False),
    ("missing field", [b'{"proto":"vtr-sim","version":1,"cmd":"step","seq":904,"stamp":0,"v":0,"duration":0.1}'], True),
    ("wrong type", [b'{"proto":"vtr-sim","version":1,"cmd":"step","seq":905,"stamp":0,"v":"fast","w":0,"duration":0.1}'], True),
    ("non-finite number", [b'{"proto":"vtr-sim","version":1,"cmd":"step","seq":906,"stamp":0,"v":NaN,"w":0,"duration":0.1}'], False),
    ("extra frame", [b'{"proto": "vtr-sim", "version": 1, "cmd": "observe", "seq": 907, "stamp": 0}', b"xx"], True),
]  # fmt: skip


def check_errors(ctx: Context) -> tuple[str, str]:
    warnings = []
    for what, frames, echo in BAD_REQUESTS:
        reply = ctx.link.raw_reply(frames, what)
        if reply.ok:
            raise CheckFailed(f"a request with a {what} got ok: true; answer it with ok: false and an error")
        if echo:
            sent = json.loads(frames[0])
            if reply.seq != sent["seq"] or reply.cmd != sent["cmd"]:
                warnings.append(f"{what}: cmd/seq not echoed")
        if reply.code not in protocol.ERROR_CODES:
            warnings.append(f"{what}: no error 'code' ({', '.join(protocol.ERROR_CODES)})")
    ctx.ask("observe")  # still serving
    if warnings:
        return WARN, "; ".join(warnings[:3]) + (
            f" (and {len(warnings) - 3} more)" if len(warnings) > 3 else ""
        )
    return PASS, f"{len(BAD_REQUESTS)} bad requests answered with ok: false, then served again"


def check_session_guard(ctx: Context) -> tuple[str, str]:
    """A motion command meant for another session (the robot rebooted under the client) must be refused."""
    assert ctx.hello is not None and ctx.limits is not None
    before = ctx.ask("observe")
    stale = "x" + ctx.hello.session[:-1] if len(ctx.hello.session) > 1 else "stale"
    try:
        reply = ctx.link.ask("step", v=0.0, w=0.5 * ctx.limits.w_max, duration=ctx.dt, session=stale)
    finally:
        ctx.link.ask("stop")
    after = ctx.ask("observe")
    if reply.ok:
        raise CheckFailed(
            "a step naming another session was executed: refuse reset/step whose 'session' is not yours "
            "(code session_mismatch), they were meant for the robot before a reboot"
        )
    assert before.image is not None and after.image is not None
    if image_diff(before.image, after.image) > max(2.0, 2 * ctx.noise_floor + 1):
        raise CheckFailed("a step naming another session was refused but the robot moved anyway")
    if reply.code != "session_mismatch":
        return WARN, f"refused with code {reply.code!r}; use 'session_mismatch'"
    return PASS, "a step for another session refused (session_mismatch), the robot did not move"


def check_watchdog(ctx: Context) -> tuple[str, str]:
    """Realtime: with no new command the robot must come to rest within cmd_vel_timeout."""
    assert ctx.hello is not None and ctx.limits is not None
    if ctx.hello.mode != "realtime":
        return PASS, "lockstep: the robot never moves between requests"
    timeout = ctx.hello.cmd_vel_timeout or 0.0
    if timeout <= 0 or timeout > 5.0:
        return WARN, f"cmd_vel_timeout {timeout} s: not checked (announce 0.5 s and enforce it)"
    try:
        ctx.step(0.0, 0.5 * ctx.limits.w_max)  # the twist keeps driving after the reply...
        time.sleep(max(timeout, ctx.dt) + 0.3)  # ...until the watchdog stops it
        first = ctx.ask("observe")
        time.sleep(0.3)
        second = ctx.ask("observe")
    finally:
        ctx.link.ask("stop")
    assert first.image is not None and second.image is not None
    diff = image_diff(first.image, second.image)
    if diff > max(2.0, 2 * ctx.noise_floor + 1):
        raise CheckFailed(
            f"still turning {timeout + 0.3:.1f} s after the last step (image change {diff:.1f}/255): "
            "stop the robot when no command arrived within cmd_vel_timeout"
        )
    return PASS, f"at rest {timeout + 0.3:.1f} s after the last step (cmd_vel_timeout {timeout} s)"


def check_latency(ctx: Context, count: int = 30) -> tuple[str, str]:
    times = []
    deadline = time.monotonic() + 5.0
    while len(times) < count and time.monotonic() < deadline:
        reply = ctx.link.ask("observe")
        if not reply.ok:
            raise CheckFailed(f"observe refused: {reply.error}")
        times.append(ctx.link.last_rtt_s)
    median, p95 = percentile_ms(times, 50), percentile_ms(times, 95)
    text = f"observe round trip median {median:.2f} ms, p95 {p95:.2f} ms ({len(times)} requests)"
    if p95 > 0.3 * ctx.dt * 1000:
        return WARN, text + f": more than 30% of the {ctx.dt} s control step"
    return PASS, text


# (name, function, needs): a check is skipped when a check it needs did not pass or warn.
CHECKS: list[tuple[str, Check, tuple[str, ...]]] = [
    ("hello", check_hello, ()),
    ("hello.camera", check_hello_camera, ("hello",)),
    ("hello.clock", check_hello_clock, ("hello",)),
    ("reset", check_reset, ("hello",)),
    ("observe", check_observe, ("hello",)),
    ("image", check_image, ("observe",)),
    ("stop", check_stop, ("hello",)),
    ("step.zero", check_zero_step, ("observe",)),
    ("step.turn", check_turn, ("observe",)),
    ("stamps", check_stamps, ("observe",)),
    ("limits.enforced", check_limits_enforced, ("hello",)),
    ("errors", check_errors, ("hello",)),
    ("session.guard", check_session_guard, ("observe",)),
    ("watchdog", check_watchdog, ("observe",)),
    ("latency", check_latency, ("hello",)),
]


def run_checks(endpoint: str, timeout_s: float = 2.0, budget_s: float = 60.0) -> list[CheckResult]:
    """Run every check against ``endpoint``; never raises for a misbehaving robot, never hangs."""
    link = Link(endpoint, timeout_s)
    ctx = Context(link)
    results: list[CheckResult] = []
    passed: set[str] = set()
    deadline = time.monotonic() + budget_s
    try:
        for name, check, needs in CHECKS:
            missing = [n for n in needs if n not in passed]
            if missing:
                results.append(CheckResult(name, SKIP, f"needs {', '.join(missing)}"))
                continue
            if time.monotonic() > deadline:
                results.append(CheckResult(name, SKIP, f"time budget of {budget_s} s spent"))
                continue
            try:
                status, detail = check(ctx)
            except CheckFailed as exc:
                status, detail = FAIL, str(exc)
            except (zmq.ZMQError, OSError) as exc:
                status, detail = FAIL, f"socket error: {exc}"
            if status != FAIL:
                passed.add(name)
            results.append(CheckResult(name, status, detail))
    finally:
        link.stop_quietly()
        link.close()
    return results


def format_report(endpoint: str, results: list[CheckResult], elapsed_s: float) -> str:
    width = max(len(r.name) for r in results)
    lines = [f"vtr check-robot {endpoint}"]
    lines += [f"{r.status}  {r.name:<{width}}  {r.detail}" for r in results]
    count = {s: sum(r.status == s for r in results) for s in (PASS, WARN, FAIL, SKIP)}
    verdict = "conformant" if not count[FAIL] else "NOT conformant"
    lines.append(
        f"summary: {verdict}: {count[PASS]} passed, {count[WARN]} warnings, {count[FAIL]} failed, "
        f"{count[SKIP]} skipped in {elapsed_s:.1f} s"
    )
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("addr", metavar="ADDR", help="the robot's endpoint, e.g. tcp://127.0.0.1:5555")
    parser.add_argument(
        "--timeout", type=float, default=2.0, help="seconds to wait for each reply (default 2)"
    )
    parser.add_argument("--budget", type=float, default=60.0, help="seconds for the whole run (default 60)")
    parser.add_argument("--json", default=None, help="also write the results to this JSON file")


def run_cli(args: argparse.Namespace) -> int:
    if "://" not in args.addr:
        print(f"vtr check-robot: ADDR must be a ZeroMQ endpoint like tcp://127.0.0.1:5555, got {args.addr!r}")
        return 2
    if not (args.timeout > 0 and args.budget > 0):
        print("vtr check-robot: --timeout and --budget must be > 0", file=sys.stderr)
        return 2
    t0 = time.monotonic()
    results = run_checks(args.addr, args.timeout, args.budget)
    print(format_report(args.addr, results, time.monotonic() - t0))
    if args.json:
        from vtr.runtime.atomic import write_text_atomic

        write_text_atomic(args.json, json.dumps([asdict(r) for r in results], indent=2))
    return 1 if any(r.status == FAIL for r in results) else 0
