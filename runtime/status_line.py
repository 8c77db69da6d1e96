"""One live line on a terminal: `vtr repeat`'s status while it drives, and the progress of `vtr eval` and
`vtr bench` (:class:`Progress`).

The text is made by pure functions (:func:`repeat_status`, :func:`progress_text`); :class:`LiveLine` writes it
over itself with a carriage return, and only to a terminal: piped or redirected output, and a log file, stay as
they were. A line is cut to the terminal's width (a wrapped line could not be overwritten) and rewritten at
most ``LiveLine.every_s`` apart, except the last, which is always shown.
"""

from __future__ import annotations

import math
import shutil
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, wait
from typing import TYPE_CHECKING, Any, TextIO, TypeVar

from vtr.runtime.kinematics import wrap_angle

if TYPE_CHECKING:
    from vtr.runtime.route import Route

T = TypeVar("T")

#: Seconds between rewrites of the line (a lockstep simulator steps far faster than anyone reads).
REFRESH_S = 0.1
#: On a stream that is not a terminal (a log file), :class:`Progress` writes a plain line at most this often (s):
#: a long job run under nohup shows how far it got, a short one writes nothing.
LOG_EVERY_S = 60.0
#: Below this |v| (m/s) or |w| (rad/s) a command prints as 0.
_TINY = 5e-4


class LiveLine:
    """A line rewritten in place on ``stream`` when it is a terminal (``enabled`` None: ask the stream)."""

    def __init__(self, stream: TextIO | None = None, enabled: bool | None = None, every_s: float = REFRESH_S):
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = _is_terminal(self.stream) if enabled is None else enabled
        self.every_s = every_s
        self._shown = False
        self._last = -math.inf

    def show(self, text: str, force: bool = False) -> None:
        """Rewrite the line with ``text`` (at most every ``every_s`` seconds unless ``force``)."""
        now = time.monotonic()
        if not self.enabled or (not force and now - self._last < self.every_s):
            return
        self._last = now
        width = shutil.get_terminal_size((100, 24)).columns - 1
        self._write("\r" + text[:width] + "\x1b[K")  # clear what a longer line left behind
        self._shown = self.enabled

    def print(self, text: str) -> None:
        """A line that stays (a finished run), printed above the live one."""
        if not self.enabled:
            return
        self._write("\r\x1b[K" + text + "\n")
        self._shown = False
        self._last = -math.inf

    def close(self) -> None:
        """End the live line so that what is printed next starts on a line of its own."""
        if self._shown:
            self._write("\n")
            self._shown = False

    def _write(self, text: str) -> None:
        """Write, or fall silent for good: a closed terminal must not end what the line only shows."""
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):
            self.enabled = False


def _is_terminal(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, OSError, ValueError):  # no such method, or a closed stream
        return False


# ------------------------------------------------------------------------------------ vtr repeat


def taught_seconds(route: Route) -> float | None:
    """How long the teach drove, from the route: subgoals a fixed number of control steps apart give
    (L - 1) x every x dt; otherwise each gap's taught command over its taught poses (None where unknown)."""
    dt = float(route.spacing.get("dt", route.dt))
    if route.steps_between is not None and dt > 0:
        return (len(route) - 1) * route.steps_between * dt
    poses, commands = route.poses, route.commands
    if len(poses) < 2:
        return None
    total = 0.0
    for k in range(len(poses) - 1):
        (x0, y0, a0), (x1, y1, a1), (v, w) = poses[k], poses[k + 1], commands[k]
        turn = abs(wrap_angle(a1 - a0))
        legs = [math.hypot(x1 - x0, y1 - y0) / abs(v) if abs(v) > _TINY else 0.0]
        legs.append(turn / abs(w) if abs(w) > _TINY else 0.0)
        total += max(legs)
    return total if math.isfinite(total) and total > 0 else None


def _seconds(t: float) -> str:
    return f"{t:.1f} s" if t < 600 else f"{int(t // 60)} min {int(t % 60):02d} s"


def repeat_status(
    record: Any,
    total: int,
    elapsed_s: float,
    taught_s: float | None = None,
    confidence: float | None = None,
    waited_s: float | None = None,
    wait_s: float | None = None,
) -> str:
    """The status line of one step record (runtime.repeat_types.StepRecord): the subgoal steered to (i/N,
    from 1; N/N once finished), the image match (the record's error), the localiser's confidence when there is
    one, the command, time against the teach's; a wait for the way to clear (``waited_s`` of ``wait_s``) or the
    end of the run instead of the command."""
    status = getattr(record, "status", None)
    finished = status is not None and status.value == "finished"
    shown = total if finished else min(int(record.subgoal) + 1, total)  # counted from 1, as a person would
    parts = [f"subgoal {shown}/{total}"]
    if math.isfinite(record.error):
        parts.append(f"match {record.error:.3g}")  # raw 0..255 or matcher units
    if confidence is not None and math.isfinite(confidence):
        parts.append(f"confidence {confidence:.2f}")
    if status is not None:
        parts.append(f"ended: {status.value}")
    elif waited_s is not None:
        of = f" of {wait_s:g} s" if wait_s is not None else ""
        parts.append(f"waiting: way blocked ({waited_s:.1f} s{of})")
    else:
        v = 0.0 if abs(record.v) < _TINY else record.v
        w = 0.0 if abs(record.w) < _TINY else record.w
        parts.append(f"v {v:+.2f} m/s  w {w:+.2f} rad/s")
    parts.append(f"{_seconds(elapsed_s)}" + (f" of {_seconds(taught_s)} taught" if taught_s else ""))
    return "  ".join(parts)


class RepeatStatusLine:
    """The Repeater's ``on_step`` observer showing :func:`repeat_status` on a :class:`LiveLine`.

    Time runs on the robot's clock (its stamps: a lockstep simulator's time, as the teach's), else the wall
    clock. ``confidence`` is asked for the localiser's confidence after each step (None: there is none);
    ``wait_s`` is how long the Repeater waits for a blocked way.
    """

    def __init__(
        self,
        total: int,
        taught_s: float | None = None,
        wait_s: float | None = None,
        confidence: Callable[[], float | None] | None = None,
        line: LiveLine | None = None,
    ) -> None:
        self.total, self.taught_s, self.wait_s = total, taught_s, wait_s
        self.confidence = confidence or (lambda: None)
        self.line = line or LiveLine()
        self._t0: tuple[float | None, float] | None = None

    def _elapsed(self, stamp: float | None) -> float:
        now = time.monotonic()
        if self._t0 is None:
            self._t0 = (stamp, now)
        first, wall0 = self._t0
        if stamp is not None and first is not None and math.isfinite(stamp) and math.isfinite(first):
            return max(0.0, stamp - first)
        return now - wall0

    def __call__(self, record: Any) -> None:
        if not self.line.enabled:
            return
        elapsed = self._elapsed(record.stamp)
        waited = getattr(record, "waited_s", None)
        text = repeat_status(
            record, self.total, elapsed, self.taught_s, self.confidence(), waited, self.wait_s
        )
        self.line.show(text, force=record.status is not None)

    def close(self) -> None:
        self.line.close()


# ------------------------------------------------------------------------------------ eval, bench


def progress_text(
    label: str, done: int, total: int | None, elapsed_s: float, last: str = "", eta: bool = True
) -> str:
    """``label: done/total (pct) elapsed[, about R left][: last]`` (the time left where the pieces are alike:
    ``eta``)."""
    if total:
        left = elapsed_s / done * (total - done) if done and eta else None
        text = f"{label}: {done}/{total} ({100 * done / total:.0f}%), {_seconds(elapsed_s)}"
        if left is not None and done < total:
            text += f", about {_seconds(left)} left"
    else:
        text = f"{label}: {done} done, {_seconds(elapsed_s)}"
    return text + (f": {last}" if last else "")


class Progress:
    """Done/total of a long job on a :class:`LiveLine` (stderr; ``quiet`` silences it). On a stream that is not
    a terminal, a plain line every ``log_every_s`` seconds instead, and the last one at the end if any was.

    ``advance(what)`` after each finished piece; ``start(what)`` before a long one; ``close()`` at the end (or
    use it as a context manager). ``eta``: say the time left, for pieces that take about as long as each other."""

    def __init__(
        self,
        label: str,
        total: int | None = None,
        quiet: bool = False,
        stream: TextIO | None = None,
        eta: bool = True,
        log_every_s: float = LOG_EVERY_S,
    ) -> None:
        self.label, self.total, self.done, self.eta = label, total, 0, eta
        self.line = LiveLine(stream, enabled=False if quiet else None)
        self._t0 = time.monotonic()
        self._what = ""
        # a log, not a terminal: plain lines, the first after log_every_s
        self._log_every = log_every_s if not (quiet or self.line.enabled) else math.inf
        self._logged, self._unlogged, self.logged_lines = self._t0, "", 0
        self.line.show(progress_text(label, 0, total, 0.0), force=True)

    def advance(self, what: str = "", n: int = 1) -> None:
        self.done += n
        self.show(what, force=self.total is not None and self.done >= self.total)

    def start(self, what: str) -> None:
        self.show(f"{what} ...", force=True)

    def show(self, what: str | None = None, force: bool = False) -> None:
        """The line now (``what`` None: the last one said, with the clock moved on)."""
        self._what = self._what if what is None else what
        now = time.monotonic()
        text = progress_text(self.label, self.done, self.total, now - self._t0, self._what, self.eta)
        self.line.show(text, force=force)
        self._unlogged = text
        if now - self._logged >= self._log_every:
            self._log(now)

    def as_completed(self, futures: Iterable[Future[T]], every_s: float = 1.0) -> Iterator[Future[T]]:
        """``futures`` as they finish, the clock on the line moving on while none does (pool workers)."""
        pending = set(futures)
        while pending:
            done, pending = wait(pending, timeout=every_s, return_when=FIRST_COMPLETED)
            if not done:
                self.show()
            yield from done

    def _log(self, now: float) -> None:
        self._logged, self.logged_lines = now, self.logged_lines + 1
        try:
            self.line.stream.write(self._unlogged + "\n")
            self.line.stream.flush()
        except (OSError, ValueError):  # a closed log must not end the job
            self._log_every = math.inf
        self._unlogged = ""

    def close(self) -> None:
        if self._unlogged and self.logged_lines:  # a long job's log ends with where it ended
            self._log(time.monotonic())
        self.line.close()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
