"""Keys from a terminal for `vtr teach --drive` and `--follow`: raw mode, key names, and the step teleop.

The key map changes speed and turn in steps, as a robot's keyboard teleop does (the idea of ROS's
``teleop_twist_keyboard`` and ``turtlebot3_teleop``: a key press changes the command, which then holds until
the next press): up/``w`` faster, down/``s`` slower (below zero: backwards), left/``a`` turn left (counter-
clockwise, REP-103), right/``d`` turn right, space stops, ``q`` or Enter finishes and saves, Esc or Ctrl-C
aborts. In raw mode Ctrl-C arrives as a byte (no SIGINT), so the teach ends through its own exit path.

Only the standard library (termios, tty, select, signal): this runs on the robot board.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import termios
import threading
import tty
from collections.abc import Iterator
from dataclasses import dataclass

#: What each key does: (speed steps, turn steps) or one of "stop", "finish", "abort".
KEYMAP: dict[str, tuple[int, int] | str] = {
    "up": (1, 0),
    "w": (1, 0),
    "down": (-1, 0),
    "s": (-1, 0),
    "left": (0, 1),
    "a": (0, 1),
    "right": (0, -1),
    "d": (0, -1),
    "space": "stop",
    "q": "finish",
    "enter": "finish",
    "esc": "abort",
    "ctrl-c": "abort",
    "eof": "abort",  # the terminal closed: nobody is at the keys any more
}
#: The help line shown before a drive starts.
HELP = (
    "up/w faster, down/s slower, left/a and right/d turn, space stops, q or Enter saves, Esc or Ctrl-C aborts"
)
FOLLOW_HELP = (
    "recording while the robot is driven by its own joystick: q or Enter saves, Esc or Ctrl-C aborts"
)
_ARROWS = {b"A": "up", b"B": "down", b"C": "right", b"D": "left"}
_BYTES = {b" ": "space", b"\r": "enter", b"\n": "enter", b"\x03": "ctrl-c", b"\x04": "ctrl-c"}
#: How long a lone Esc byte waits for the rest of an arrow key's sequence before it counts as Esc.
ESC_WAIT_S = 0.05


def decode_keys(data: bytes) -> tuple[list[str], bytes]:
    """Key names in ``data`` and the bytes of a sequence not yet complete (an arrow key split across reads).
    Unknown keys are named by their character (they do nothing in :data:`KEYMAP`)."""
    keys: list[str] = []
    i = 0
    while i < len(data):
        byte = data[i : i + 1]
        if byte == b"\x1b":
            if i + 1 == len(data) or (data[i + 1 : i + 2] in (b"[", b"O") and i + 2 == len(data)):
                return keys, data[i:]  # maybe the start of an arrow key
            if data[i + 1 : i + 2] in (b"[", b"O"):
                keys.append(_ARROWS.get(data[i + 2 : i + 3], "unknown"))
                i += 3
                continue
            keys.append("esc")
            i += 1
            continue
        keys.append(_BYTES.get(byte) or byte.decode("latin-1").lower())
        i += 1
    return keys, b""


class KeyReader:
    """Keys typed on ``fd`` (a terminal in raw mode): :meth:`read` waits up to ``timeout`` seconds."""

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self._partial = b""

    def _ready(self, timeout: float) -> bool:
        return bool(select.select([self.fd], [], [], max(0.0, timeout))[0])

    def read(self, timeout: float) -> list[str]:
        if not self._ready(timeout):
            return []
        data = os.read(self.fd, 256)
        if not data:  # the terminal went away: nobody can drive any more
            return ["eof"]
        keys, self._partial = decode_keys(self._partial + data)
        if self._partial and not self._ready(ESC_WAIT_S):
            keys += ["esc"] if self._partial == b"\x1b" else ["unknown"]
            self._partial = b""
        return keys


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)


@contextlib.contextmanager
def raw_terminal(fd: int) -> Iterator[None]:
    """Raw mode on ``fd`` for the block, the previous settings restored on every way out. SIGTERM and SIGHUP (the
    terminal closed) become a KeyboardInterrupt meanwhile, so they too leave through the drive's stop."""
    saved = termios.tcgetattr(fd)
    previous = {}
    if threading.current_thread() is threading.main_thread():
        previous = {sig: signal.signal(sig, _interrupt) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        tty.setraw(fd, termios.TCSANOW)
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        with contextlib.suppress(termios.error):  # a terminal that is gone has nothing to restore
            termios.tcsetattr(fd, termios.TCSADRAIN, saved)


@dataclass
class Teleop:
    """The command a driver holds: keys move it in steps of ``v_step``/``w_step`` within the robot's limits."""

    v_max: float
    w_max: float
    v_step: float = 0.05  # m/s per press
    w_step: float = 0.1  # rad/s per press
    v: float = 0.0
    w: float = 0.0

    def press(self, key: str) -> str | None:
        """Apply one key; returns "finish" or "abort" when the key ends the drive."""
        action = KEYMAP.get(key)
        if action is None:
            return None
        if action == "stop":
            self.v = self.w = 0.0
        elif isinstance(action, tuple):
            self.v = _nudge(self.v, action[0], self.v_step, self.v_max)
            self.w = _nudge(self.w, action[1], self.w_step, self.w_max)
        else:
            return action
        return None


def _nudge(value: float, steps: int, step: float, bound: float) -> float:
    """``value`` moved ``steps`` steps, on the grid of ``step`` (no 0.30000000000000004), within +-``bound``."""
    if steps == 0:
        return value
    return max(-bound, min(bound, round((value + steps * step) / step) * step + 0.0))
