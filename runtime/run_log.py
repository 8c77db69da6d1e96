"""`vtr repeat --log`: the JSON-lines log, one object per line, every line written whole or not at all.

A full disk (or any failed write) cuts the file back to its last whole line and raises :class:`LogWriteError`
naming the file, so what is left always parses line by line (runtime/daemon.py documents the lines).
"""

from __future__ import annotations

import json
import os
from typing import IO, Any


class LogWriteError(OSError):
    """The log could not be written: the message names the file and what it still holds."""


class JsonLinesLog:
    """Write JSON objects as lines to ``path`` (``stream``: an already open binary file, for tests)."""

    def __init__(self, path: str | os.PathLike[str], stream: IO[bytes] | None = None) -> None:
        self.path = os.fspath(path)
        # unbuffered: a line reaches the file in this call, and a failed write leaves nothing queued to retry
        self._file = stream if stream is not None else open(self.path, "wb", buffering=0)  # noqa: SIM115
        self._whole = 0  # bytes of whole lines in the file
        self.lines = 0

    def write(self, obj: Any) -> None:
        data = (json.dumps(obj, allow_nan=False, default=float) + "\n").encode()
        view = memoryview(data)
        try:
            while view:  # a raw write may take part of the line: write the rest, or fail
                written = self._file.write(view)
                view = view[written if written is not None else len(view) :]
            self._file.flush()
        except OSError as exc:
            self._cut_back()
            why = exc.strerror or str(exc) or type(exc).__name__
            raise LogWriteError(
                f"cannot write the log {self.path}: {why}; it keeps the {self.lines} whole lines before"
            ) from None
        self._whole += len(data)
        self.lines += 1

    def _cut_back(self) -> None:
        """Drop a torn last line (best effort: a file that cannot be truncated keeps it)."""
        try:
            self._file.truncate(self._whole)
            self._file.seek(self._whole)
        except (OSError, ValueError):
            pass

    def close(self) -> None:
        self._file.close()

    def remove(self) -> None:
        """Close and delete the file (a start that failed after it was opened)."""
        self.close()
        try:
            os.unlink(self.path)
        except OSError:
            pass
