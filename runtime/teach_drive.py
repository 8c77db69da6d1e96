"""Teach by driving: `vtr teach --drive` (keyboard teleop) and `vtr teach --follow` (someone else drives).

Both record through the one teach recorder (``runtime.teach_record``) with the route's spacing rule, once per
control period ``dt`` of the wall clock, starting where the robot stands (no reset: a real robot is placed by
hand). Keys come from the terminal in raw mode (``runtime.teleop_keys``); a live status line (speed, turn,
distance driven, subgoals, the robot's state) is redrawn in place when stdout is a terminal.

- ``--drive``: every period sends the held command as a ``step`` of ``dt``, pressed or not, so the robot's
  command timeout never fires while a driver holds a speed. The command stays within the robot's limits
  (``hello``) and, on a robot with a range scanner, within what its scan leaves free (``runtime.safety``, as
  in a repeat). Every way out (finish, Esc, Ctrl-C, a lost robot, an error) sends a stop.
- ``--follow``: sends no motion command at all, only ``observe``: the robot is driven by its own joystick,
  and a command from here (even a stop) would fight the driver. Each period's motion is the executed twist
  the robot reports (hello's ``twist``, docs/PROTOCOL.md) or, without one, the change of its pose.

A drive that ends with ``q``/Enter returns the route; Esc, Ctrl-C or a closed terminal return None (nothing
is saved). The robot standing still adds no subgoals (``TeachRecorder.step``'s ``moving``).
"""

from __future__ import annotations

import math
import os
import time
from typing import Any, TextIO

from vtr.runtime.kinematics import wrap_angle
from vtr.runtime.protocol import BadFrameError, Limits
from vtr.runtime.robot import Observation, Robot, RobotError, safe_stop
from vtr.runtime.safety import limit_twist
from vtr.runtime.teach_record import TeachRecorder
from vtr.runtime.teleop_keys import KEYMAP, KeyReader, Teleop

#: Below these an executed twist (m/s, rad/s) or a pose change per period (m, rad) counts as standing still.
STILL_V, STILL_W = 1e-3, 1e-3
STILL_D, STILL_YAW = 1e-4, 1e-4


class StatusLine:
    """One line redrawn in place (carriage return, erase to its end), only on a terminal."""

    def __init__(self, out: TextIO | None) -> None:
        self.out = out if out is not None and out.isatty() else None

    def show(self, text: str) -> None:
        if self.out is not None:  # cut to the terminal's width: a wrapped line could not be redrawn in place
            self.out.write(f"\r{text[: self.width - 1]}\x1b[K")
            self.out.flush()

    @property
    def width(self) -> int:
        try:
            return os.get_terminal_size(self.out.fileno()).columns or 80
        except (OSError, ValueError, AttributeError):
            return 80

    def end(self) -> None:
        if self.out is not None:
            self.out.write("\r\n")
            self.out.flush()


class Odometer:
    """Distance driven: along the poses when the robot reports them, else the commanded speed times dt."""

    def __init__(self) -> None:
        self.metres = 0.0
        self._pose: tuple[float, float, float] | None = None

    def add(self, obs: Observation, v: float, dt: float) -> None:
        if obs.pose is None or self._pose is None:
            self.metres += 0.0 if obs.pose is not None else abs(v) * dt
        else:
            self.metres += math.hypot(obs.pose[0] - self._pose[0], obs.pose[1] - self._pose[1])
        self._pose = obs.pose


def _status(v: float, w: float, odo: Odometer, rec: TeachRecorder, robot: str) -> str:
    return f"v {v:+.2f} m/s  w {w:+.2f} rad/s  {odo.metres:6.2f} m  {len(rec):4d} subgoals  robot: {robot}"


def _robot_state(obs: Observation, note: str = "") -> str:
    return note or ("CONTACT" if obs.collided else "ok")


class _Ticker:
    """Control periods of ``dt`` on the wall clock; keys read while waiting for the next one."""

    def __init__(self, keys: KeyReader, dt: float) -> None:
        self.keys, self.dt = keys, dt
        self.next = time.monotonic()

    def wait(self, on_key: Any) -> str | None:
        """Deliver keys to ``on_key`` until the next period starts; returns "finish"/"abort" when one says so."""
        while True:
            now = time.monotonic()
            for key in self.keys.read(max(0.0, self.next - now)):
                end = on_key(key)
                if end is not None:
                    return end
            if time.monotonic() >= self.next:
                self.next = max(self.next + self.dt, time.monotonic() - self.dt)
                return None


def drive(
    robot: Robot, cfg: Any, keys: KeyReader, limits: Limits, out: TextIO | None, first: Observation
) -> TeachRecorder | None:
    """Keyboard teleop from ``first`` on; the recorder when the driver finished, None when aborted.
    Raises RobotError when the robot is lost. Sends a stop on every way out."""
    teleop = Teleop(limits.v_max, limits.w_max)
    rec, odo, line = TeachRecorder(cfg, first), Odometer(), StatusLine(out)
    ticker = _Ticker(keys, cfg.dt)
    obs, note = first, ""
    try:
        while True:
            end = ticker.wait(teleop.press)
            if end is not None:
                return rec if end == "finish" else None
            safe = limit_twist(teleop.v, teleop.w, obs.scan)  # the scan's stop zone, as in a repeat
            v, w = safe.v, safe.w
            try:
                obs = robot.step(v, w, cfg.dt)
                note = safe.describe() if safe.limited else ""
            except BadFrameError as exc:  # one bad reply: the robot was stopped, drive on
                note = f"bad reply ({exc})"[:60]
                continue
            rec.step(v, w, obs, moving=(v, w) != (0.0, 0.0))
            odo.add(obs, v, cfg.dt)
            line.show(_status(v, w, odo, rec, _robot_state(obs, note)))
    finally:
        safe_stop(robot)
        line.end()


def executed(prev: Observation, obs: Observation, dt: float) -> tuple[float, float, bool]:
    """(v, w, moving) over one period: the reported twist, else the pose change over the time the robot's stamps
    say passed (``dt`` when they do not advance: a late reply must not read as a burst of speed)."""
    if obs.twist is not None:
        v, w = obs.twist
        return v, w, abs(v) > STILL_V or abs(w) > STILL_W
    if obs.pose is None or prev.pose is None:
        raise RobotError(
            "the robot reports neither its executed twist nor its pose: --follow cannot see it move"
        )
    dx, dy = obs.pose[0] - prev.pose[0], obs.pose[1] - prev.pose[1]
    dyaw = wrap_angle(obs.pose[2] - prev.pose[2])
    yaw = prev.pose[2]
    elapsed = obs.stamp - prev.stamp if obs.stamp - prev.stamp > 1e-6 else dt
    v = (dx * math.cos(yaw) + dy * math.sin(yaw)) / elapsed
    return v, dyaw / elapsed, math.hypot(dx, dy) > STILL_D or abs(dyaw) > STILL_YAW


def follow(
    robot: Robot, cfg: Any, keys: KeyReader, out: TextIO | None, first: Observation
) -> TeachRecorder | None:
    """Record while someone else drives (observe only) from ``first`` on; None when aborted."""
    rec, odo, line = TeachRecorder(cfg, first), Odometer(), StatusLine(out)
    ticker = _Ticker(keys, cfg.dt)
    prev = first
    try:
        while True:
            end = ticker.wait(lambda key: KEYMAP.get(key) if KEYMAP.get(key) in ("finish", "abort") else None)
            if end is not None:
                return rec if end == "finish" else None
            try:
                obs = robot.observe()
            except BadFrameError as exc:
                line.show(f"bad reply ({exc})"[:80])
                continue
            v, w, moving = executed(prev, obs, cfg.dt)
            rec.step(v, w, obs, moving)
            odo.add(obs, v, cfg.dt)
            line.show(_status(v, w, odo, rec, _robot_state(obs, "" if moving else "standing")))
            prev = obs
    finally:
        line.end()
