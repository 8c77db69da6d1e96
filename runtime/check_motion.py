"""The checks of `vtr check-robot` that move the robot: a zero step, a turn in place and back, steps it must
refuse (beyond its limits, or meant for another session), the realtime command timeout (the watchdog), and the
executed twist a robot announces (a turn must show in it)."""

from __future__ import annotations

import math
import time
from typing import Any

from vtr.runtime.check_link import PASS, WARN, CheckFailed, Context, announced, image_diff, unannounced
from vtr.runtime.kinematics import wrap_angle
from vtr.runtime.reply_codec import twist_from_wire

#: A turn this large must change the view (radians).
TURN_ANGLE = 0.3


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
        dyaw = wrap_angle(turned.pose[2] - start.pose[2])
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


def check_twist(ctx: Context) -> tuple[str, str]:
    """The executed twist (docs/PROTOCOL.md, 'Executed twist'): when hello announces it, every image reply
    carries one, and a turn in place reports w > 0 (counter-clockwise positive) while it turns."""
    assert ctx.hello is not None and ctx.limits is not None
    w = 0.5 * ctx.limits.w_max
    replies = [ctx.ask("observe")]
    try:  # three steps: a measured twist may lag the command by a step or two
        replies += [ctx.step(0.0, w) for _ in range(3)]
        ctx.step(0.0, -w)
        ctx.step(0.0, -w)
        ctx.step(0.0, -w)
    finally:
        ctx.link.ask("stop")
    if ctx.hello.twist is None:
        return unannounced(
            replies, "twist", "Executed twist", "not reported: `vtr teach --follow` goes by the pose"
        )
    twists = announced(replies, "twist", twist_from_wire)
    v_seen, w_seen = twists[-1]
    if not w_seen > 0.2 * w:
        raise CheckFailed(
            f"turning in place at w={w:g} rad/s the robot reported w={w_seen:g}: report the twist it executes, "
            "counter-clockwise positive (REP-103)"
        )
    return PASS, f"{ctx.hello.twist}; turning at w={w:g} rad/s reported v={v_seen:+.3f}, w={w_seen:+.3f}"


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
