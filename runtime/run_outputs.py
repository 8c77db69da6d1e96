"""Where a repeat run goes besides the JSON-lines log: a ROS 2 MCAP bag (runtime/mcap_log.py) and a live
Foxglove view (runtime/foxglove_live.py). Both are optional extras, imported only when asked for."""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from vtr.runtime.mcap_log import step_fields


class RunOutputs:
    """Open the requested outputs; ``chain(callback)`` makes the Repeater's ``on_step`` feed them all.

    Use as a context manager: leaving it closes the outputs (the MCAP file is moved into place even when the
    run raised, so a crashed run is still there to look at).
    """

    def __init__(self, mcap: str | None, foxglove_port: int | None, route_images: np.ndarray) -> None:
        self.route_images = route_images
        self.sinks: list[Any] = []
        try:
            if mcap:
                from vtr.runtime.mcap_log import McapRunWriter

                self.sinks.append(McapRunWriter(mcap))
            if foxglove_port is not None:
                from vtr.runtime.foxglove_live import FoxgloveLive

                live = FoxgloveLive(foxglove_port)
                self.sinks.append(live)
                print(
                    f"vtr repeat: live view for Foxglove on ws://127.0.0.1:{live.port}",
                    file=sys.stderr,
                    flush=True,
                )
        except BaseException:
            self.close()
            raise

    def chain(self, callback: Callable[[Any], None] | None = None) -> Callable[[Any], None] | None:
        """An ``on_step`` calling ``callback`` (the log) and every output; None when there is nothing to feed."""
        if not self.sinks:
            return callback

        def on_step(record: Any) -> None:
            if callback is not None:
                callback(record)
            fields = step_fields(record, self.route_images)
            if fields is not None:
                for sink in self.sinks:
                    sink.record(fields)

        return on_step

    def finish(self, summary: Mapping[str, Any]) -> None:
        for sink in self.sinks:
            if hasattr(sink, "record_summary"):
                sink.record_summary(summary)

    def close(self) -> None:
        for sink in self.sinks:
            sink.close()
        self.sinks = []

    def __enter__(self) -> RunOutputs:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
