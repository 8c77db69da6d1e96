"""`vtr check-robot ADDR`: a conformance checker for a robot bridge (or simulator) speaking runtime/protocol.py.

In the spirit of gymnasium's env_checker: small named checks, each one line (PASS / WARN / FAIL / SKIP and what
to fix), a summary, exit status 1 when anything failed. It talks raw ZeroMQ so that it can send requests the
runtime's client would never send (malformed, beyond the limits). Every request has a timeout, a timed-out socket
is rebuilt, and the whole run has a time budget: it never hangs.

The robot moves: zero steps, a turn in place of about 0.3 rad and back, and steps the robot must refuse. It ends
with a ``stop``. Run it with the robot in free space. A robot that announces a range scanner in ``hello`` must send
a matching scan with every image (check ``scan``), one that announces its executed twist a twist that shows a turn
(check ``twist``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict, dataclass

import numpy as np
import zmq

from vtr.runtime import protocol
from vtr.runtime.check_link import (
    FAIL,
    PASS,
    SKIP,
    WARN,
    Check,
    CheckFailed,
    Context,
    Link,
    announced,
    image_diff,
    percentile_ms,
    unannounced,
)
from vtr.runtime.check_motion import (
    check_limits_enforced,
    check_session_guard,
    check_turn,
    check_twist,
    check_watchdog,
    check_zero_step,
)
from vtr.runtime.contracts import CONTROL_DT, CameraSpec
from vtr.runtime.hello import CameraMismatchError, fit_model, hello_warnings, read_hello
from vtr.runtime.model_meta import ModelMeta
from vtr.runtime.scan import scan_from_wire
from vtr.runtime.setting_spec import REQUIRED
from vtr.runtime.settings import BY_NAME, default
from vtr.runtime.settings_cli import add_arguments as add_settings
from vtr.runtime.settings_cli import from_text, resolve

#: The metadata's defaults (the input and camera the shipped model was trained at), which the image check maps
#: the robot's camera to where no --model names the model the robot will run (the runtime does not look for
#: the shipped file, whose camera range may be wider: models/training-summary.json).
TRAINED = ModelMeta()


@dataclass
class CheckResult:
    name: str
    status: str
    detail: str


def check_hello(ctx: Context) -> tuple[str, str]:
    """The hello reply arrives and is one; its fields are read one by one (``hello.fields`` reports each that is
    wrong, and the checks after it go on with a fallback for it: the shipped camera, the paper's limits)."""
    reply = ctx.link.ask("hello")
    if not reply.ok:
        raise CheckFailed(f"hello was refused: {reply.error}; hello must always succeed")
    ctx.note_stamp(reply)
    try:
        ctx.hello, ctx.hello_problems = read_hello(reply)
    except protocol.BadFrameError as exc:
        raise CheckFailed(f"hello: {exc} (docs/PROTOCOL.md, 'hello', lists what to announce)") from None
    hello = ctx.hello
    if "camera" not in ctx.hello_problems:  # else image sizes are not checked against it
        ctx.camera = (hello.camera.height, hello.camera.width)
    ctx.limits = hello.limits
    ctx.dt = min(max(CONTROL_DT, hello.dt or CONTROL_DT), hello.limits.max_duration)
    lim = hello.limits
    return PASS, (
        f"session {hello.session}; limits v_max {lim.v_max} m/s, w_max {lim.w_max} rad/s, "
        f"max_duration {lim.max_duration} s"
        + (
            " (not announced correctly: the paper's, for the checks)"
            if "limits" in ctx.hello_problems
            else ""
        )
    )


def check_hello_fields(ctx: Context) -> tuple[str, str]:
    """Every hello field that is wrong, each named; fields version 1 gained after its first text (optional)
    and deprecated names are warnings."""
    assert ctx.hello is not None
    if ctx.hello_problems:
        problems = "; ".join(ctx.hello_problems.values())
        raise CheckFailed(f"{problems} (docs/PROTOCOL.md, 'hello', lists what to announce)")
    warnings = hello_warnings(ctx.hello)
    if warnings:
        return WARN, "; ".join(warnings)
    return PASS, "every field announced, none deprecated"


def check_hello_camera(ctx: Context) -> tuple[str, str]:
    assert ctx.hello is not None
    if "camera" in ctx.hello_problems:
        return SKIP, "the camera is not announced correctly (hello.fields)"
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
    if h.mode is None or h.dt is None or {"mode", "dt"} & set(ctx.hello_problems):
        return SKIP, "mode or dt not announced (hello.fields)"
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
    """The image shows something, and how the runtime maps it to the shipped model's input (runtime.resample:
    the centre crop, the size, the field of view the model then sees), or why that model cannot take it."""
    image = ctx.image
    if image is None:
        raise CheckFailed("no image seen yet")
    if float(image.std()) == 0.0:
        return WARN, "the image is one flat colour: is the camera covered or not streaming?"
    height, width = image.shape[:2]
    text = f"{width}x{height} rgb8, mean {image.mean():.0f}, std {image.std():.0f}"
    announced = ctx.hello is not None and "camera" not in ctx.hello_problems
    camera = ctx.hello.camera if announced else CameraSpec(width, height, None, None)  # type: ignore[union-attr]
    trained = f"a model of the {TRAINED.camera_fov_deg:g} deg / {TRAINED.camera_height_m:.2f} m camera"
    which = trained if ctx.model is None else "the model"
    try:
        mapping, notes = fit_model(camera, ctx.model or TRAINED)
    except (CameraMismatchError, ValueError) as exc:
        hint = "; pass --model to check with the model the robot will run" if ctx.model is None else ""
        return WARN, f"{text}; {which} cannot take this camera: {exc}{hint}"
    if mapping.identity:
        return PASS, "; ".join([f"{text}, {which}'s input as it is", *notes])
    return PASS, "; ".join([f"{text}; for {which}: {mapping.narrowing() or mapping.describe()}", *notes])


def check_scan(ctx: Context) -> tuple[str, str]:
    """The range scan: every image reply carries one matching the scanner hello announced, or none is
    announced (the runtime then drives with camera-only safety)."""
    assert ctx.hello is not None
    spec = ctx.hello.scan
    replies = [ctx.ask("observe"), ctx.step(0.0, 0.0)]
    if spec is None:
        return unannounced(replies, "scan", "Range scan", "no range sensor: camera-only safety")
    scans = announced(replies, "scan", lambda wire: scan_from_wire(wire, spec))
    span = math.degrees(abs(spec.angle_increment) * (spec.beams - 1))
    text = f"{spec.beams} beams over {span:.0f} deg, range_max {spec.range_max:g} m, mounted {spec.x_m:g} m ahead"
    seen = scans[-1].ranges[np.isfinite(scans[-1].ranges)]
    if seen.size == 0:
        return WARN, f"{text}; no beam sees anything within range_max: is the scanner streaming?"
    return PASS, f"{text}; nearest return {float(seen.min()):.2f} m"


def check_stop(ctx: Context) -> tuple[str, str]:
    reply = ctx.ask("stop")
    return PASS, f"stamp {reply.stamp}"


def check_stamps(ctx: Context) -> tuple[str, str]:
    if ctx.stamp_problems:
        raise CheckFailed("; ".join(ctx.stamp_problems[:3]) + ": stamps never go back within a session")
    return PASS, f"{len(ctx.stamps)} replies since the last reset, stamps never decreased"


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
    ("hello.fields", check_hello_fields, ("hello",)),
    ("hello.camera", check_hello_camera, ("hello",)),
    ("hello.clock", check_hello_clock, ("hello",)),
    ("reset", check_reset, ("hello",)),
    ("observe", check_observe, ("hello",)),
    ("image", check_image, ("observe",)),
    ("scan", check_scan, ("observe",)),
    ("stop", check_stop, ("hello",)),
    ("step.zero", check_zero_step, ("observe",)),
    ("step.turn", check_turn, ("observe",)),
    ("twist", check_twist, ("observe",)),
    ("stamps", check_stamps, ("observe",)),
    ("limits.enforced", check_limits_enforced, ("hello",)),
    ("errors", check_errors, ("hello",)),
    ("session.guard", check_session_guard, ("observe",)),
    ("watchdog", check_watchdog, ("observe",)),
    ("latency", check_latency, ("hello",)),
]


def run_checks(
    endpoint: str,
    timeout_s: float = default("check-robot.timeout"),
    budget_s: float = default("check-robot.budget"),
    model: ModelMeta | None = None,
) -> list[CheckResult]:
    """Run every check against ``endpoint``; never raises for a misbehaving robot, never hangs. ``model``: the
    metadata of the model the robot will run, whose cameras the image check compares with (None: the camera
    the shipped model was trained at, ``TRAINED``)."""
    link = Link(endpoint, timeout_s)
    ctx = Context(link, model=model)
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
    parser.add_argument(
        "robot.address",
        metavar="ADDR",
        nargs="?",
        type=from_text(BY_NAME["robot.address"]),
        default=argparse.SUPPRESS,
        help="the robot's endpoint, e.g. tcp://127.0.0.1:5555 (or address in the config file's [robot])",
    )
    add_settings(parser, "check-robot", skip=("robot.address",))  # --config, --model, --timeout, --budget
    parser.add_argument("--json", default=None, help="also write the results to this JSON file")


def run_cli(args: argparse.Namespace) -> int:
    try:
        settings = resolve(args, "check-robot", required=False)
    except ValueError as exc:
        print(f"vtr check-robot: {exc}", file=sys.stderr)
        return 2
    addr = settings["robot.address"]
    if addr is REQUIRED:
        print("vtr check-robot: needs ADDR (or address in the config file's [robot])", file=sys.stderr)
        return 2
    model = None
    if settings["repeat.model"] is not REQUIRED:
        from vtr.runtime.policy import ModelMismatchError, OnnxPolicy

        try:
            model = OnnxPolicy(settings["repeat.model"]).meta
        except (OSError, ValueError, ModelMismatchError) as exc:
            print(f"vtr check-robot: --model {settings['repeat.model']}: {exc}", file=sys.stderr)
            return 2
    t0 = time.monotonic()
    results = run_checks(addr, settings["check-robot.timeout"], settings["check-robot.budget"], model)
    print(format_report(addr, results, time.monotonic() - t0))
    if args.json:
        from vtr.runtime.atomic import write_text_atomic

        write_text_atomic(args.json, json.dumps([asdict(r) for r in results], indent=2))
    return 1 if any(r.status == FAIL for r in results) else 0
