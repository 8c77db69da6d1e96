"""The evaluation's process pool, which Ctrl-C stops at once.

A plain ``ProcessPoolExecutor`` leaving its ``with`` block on KeyboardInterrupt waits for every task already
queued to its workers, and a worker hit by the terminal's SIGINT reports the interrupt as that task's result and
takes the next: `vtr eval` took 14-20 s to stop. Here the workers ignore SIGINT (the parent decides), and an
exception in the parent (Ctrl-C included) cancels the queued tasks and terminates the workers.
"""

from __future__ import annotations

import multiprocessing as mp
import signal
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager


def _ignore_interrupts() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextmanager
def process_pool(workers: int) -> Iterator[ProcessPoolExecutor]:
    """A pool of ``workers`` spawned processes (fresh interpreters: no forked onnxruntime or torch thread
    pools), shut down cleanly on success and stopped at once on any exception."""
    pool = ProcessPoolExecutor(
        max_workers=workers, mp_context=mp.get_context("spawn"), initializer=_ignore_interrupts
    )
    try:
        yield pool
    except BaseException:
        stop(pool)
        raise
    pool.shutdown(wait=True)


def stop(pool: ProcessPoolExecutor) -> None:
    """Cancel what has not started and terminate the workers (what has started is abandoned)."""
    processes = list((getattr(pool, "_processes", None) or {}).values())  # the stdlib has no public handle
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=5)
