"""A command run in a pseudo-terminal, as a person at a keyboard runs it: keys in, the screen out."""

from __future__ import annotations

import os
import select
import subprocess
import sys
import termios
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


class Terminal:
    """``python -m vtr.cli ARGS`` with a pseudo-terminal as its stdin, stdout and stderr."""

    def __init__(self, *args: str) -> None:
        master, slave = os.openpty()
        self.fd = master
        #: The terminal's modes before the program starts (read later, they race its switch to raw mode).
        self.cooked = termios.tcgetattr(master)
        self.screen = b""
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "vtr.cli", *args],
            stdin=slave,
            stdout=slave,
            stderr=slave,
            cwd=ROOT,
            start_new_session=True,  # its own session: the pty becomes its controlling terminal
        )
        os.close(slave)

    def read(self, seconds: float) -> None:
        """Collect what the program writes for ``seconds``."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if select.select([self.fd], [], [], 0.02)[0]:
                try:
                    self.screen += os.read(self.fd, 65536)
                except OSError:  # the program exited and closed the terminal
                    return

    def wait_for(self, text: bytes, timeout: float = 60.0) -> None:
        end = time.monotonic() + timeout
        while text not in self.screen:
            assert time.monotonic() < end, f"{text!r} never shown; the screen: {self.text()[-800:]}"
            assert self.proc.poll() is None or text in self.screen, f"exited: {self.text()[-800:]}"
            self.read(0.05)

    def press(self, keys: bytes, then: float = 0.0) -> None:
        os.write(self.fd, keys)
        self.read(then)

    def finish(self, timeout: float = 30.0) -> int:
        """Wait for the exit; its code. The screen keeps everything shown."""
        end = time.monotonic() + timeout
        while self.proc.poll() is None and time.monotonic() < end:
            self.read(0.05)
        if self.proc.poll() is None:
            self.proc.kill()
        self.read(0.2)
        os.close(self.fd)
        return self.proc.wait(5)

    def text(self) -> str:
        return self.screen.decode(errors="replace")
