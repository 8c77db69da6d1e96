"""Where a repeat run goes: the JSON-lines log (runtime/run_log.py), a ROS 2 MCAP bag (runtime/mcap_log.py) and a
live Foxglove view (runtime/foxglove_live.py). The last two are optional extras, imported only when asked for.

Every output is checked (:func:`check_outputs`, before the model is even loaded) and opened the same way: the
folders above a path are created when missing, and a start that fails on any of them takes away what the others
had created, so a refused start leaves nothing behind.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime.mcap_log import step_fields
from vtr.runtime.paths import MadeFolders, check_output
from vtr.runtime.run_log import JsonLinesLog


class OutputWriteError(OSError):
    """An output failed during the run: the message names the flag and the file."""


def check_outputs(log: str | None, mcap: str | None) -> None:
    """ValueError (one line naming the flag) for a --log or --mcap that could not be written; creates nothing."""
    if log:
        check_output(log, "--log")
    if mcap:
        check_output(mcap, "--mcap", folder=Path(mcap).suffix != ".mcap")
    if log and mcap and Path(log).absolute() == Path(mcap).absolute():
        raise ValueError(f"--log and --mcap name the same file {log}; give each its own")


class RunOutputs:
    """Open the requested outputs; ``chain()`` is the Repeater's ``on_step`` feeding them all, ``finish`` writes
    the summary to each.

    Use as a context manager: leaving it closes the outputs (the MCAP file is moved into place even when the
    run raised, so a crashed run is still there to look at).
    """

    def __init__(
        self,
        route_images: np.ndarray,
        log: str | None = None,
        mcap: str | None = None,
        foxglove_port: int | None = None,
    ) -> None:
        check_outputs(log, mcap)
        self.route_images = route_images
        self.log: JsonLinesLog | None = None
        self.sinks: list[Any] = []
        folders = MadeFolders()
        try:
            if foxglove_port is not None:  # first: it creates no file
                from vtr.runtime.foxglove_live import FoxgloveLive

                live = FoxgloveLive(foxglove_port)
                self.sinks.append(live)
            if mcap:
                from vtr.runtime.mcap_log import McapRunWriter

                folders.make(mcap)
                self.sinks.append(McapRunWriter(mcap))
            if log:
                folders.make(log)
                self.log = JsonLinesLog(log)
        except BaseException:
            self._abort()
            folders.remove()
            raise
        if foxglove_port is not None:
            print(
                f"vtr repeat: live view for Foxglove on ws://127.0.0.1:{live.port}",
                file=sys.stderr,
                flush=True,
            )

    def chain(self) -> Callable[[Any], None] | None:
        """An ``on_step`` writing each commanded step to the log and every step to the other outputs; None when
        there is nothing to write."""
        if not self.sinks and self.log is None:
            return None

        def on_step(record: Any) -> None:
            if self.log is not None and record.commanded:
                self.log.write(record.to_log())
            fields = step_fields(record, self.route_images) if self.sinks else None
            if fields is not None:
                for sink in self.sinks:
                    _named(sink, sink.record, fields)

        return on_step

    def finish(self, summary: Mapping[str, Any]) -> None:
        """The run's summary: the log's last line, the MCAP's last message."""
        if self.log is not None:
            self.log.write({"summary": dict(summary)})
        for sink in self.sinks:
            if hasattr(sink, "record_summary"):
                _named(sink, sink.record_summary, summary)

    def _abort(self) -> None:
        """A failed start: remove every file opened so far."""
        for sink in self.sinks:
            getattr(sink, "abort", sink.close)()
        if self.log is not None:
            self.log.remove()
        self.sinks, self.log = [], None

    def close(self) -> None:
        sinks, log = self.sinks, self.log
        self.sinks, self.log = [], None
        errors = []
        for close in [s.close for s in sinks] + ([log.close] if log is not None else []):
            try:
                close()
            except OSError as exc:
                errors.append(exc)
        if errors:
            raise errors[0]

    def __enter__(self) -> RunOutputs:
        return self

    def __exit__(self, kind: object, *exc: object) -> None:
        try:
            self.close()
        except OSError:
            if kind is None:
                raise  # else the run's own error is the one to report


def _named(sink: Any, write: Callable[[Any], None], value: Any) -> None:
    """``write(value)``, an OSError (a full disk) becoming one naming the output."""
    try:
        write(value)
    except OSError as exc:
        where = getattr(sink, "path", None)
        what = f"the MCAP run {where}" if where is not None else "the live view"
        raise OutputWriteError(f"cannot write {what}: {exc.strerror or exc}") from None
