"""A process pool that Ctrl-C and SIGTERM stop at once, workers included: `vtr eval`, `vtr collect` and the
recovery views run their houses and routes in it.

A plain ``ProcessPoolExecutor`` leaving its ``with`` block on KeyboardInterrupt waits for every task already
queued to its workers, and a worker hit by the terminal's SIGINT reports the interrupt as that task's result and
takes the next: `vtr eval` took 14-20 s to stop. Here the workers ignore SIGINT (the parent decides), and an
exception in the parent (Ctrl-C included) cancels the queued tasks and terminates the workers. SIGTERM to the
parent alone (`kill PID`, a job scheduler, a CI timeout) killed it outright and left its workers running, idle,
for as long as the machine stayed up (forked ones hold their own call queue open): while the pool is open it
is Ctrl-C's interrupt.
"""

from __future__ import annotations

import multiprocessing as mp
import signal
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from typing import Any

#: The start method for workers that should share the parent's memory (its loaded data): fork, where the
#: platform has it, else spawn.
FORK_OR_SPAWN = "fork" if "fork" in mp.get_all_start_methods() else "spawn"


def _start_worker(initializer: Callable[..., object] | None, initargs: tuple[Any, ...]) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if initializer is not None:
        initializer(*initargs)


@contextmanager
def process_pool(
    workers: int,
    context: str = "spawn",
    initializer: Callable[..., object] | None = None,
    initargs: tuple[Any, ...] = (),
) -> Iterator[ProcessPoolExecutor]:
    """A pool of ``workers`` processes started by ``context`` ("spawn", the default: fresh interpreters, no forked
    onnxruntime or torch thread pools; ``FORK_OR_SPAWN`` where they should share the parent's memory), each running
    ``initializer(*initargs)`` first; shut down cleanly on success and stopped at once on any exception."""
    pool = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=mp.get_context(context),
        initializer=_start_worker,
        initargs=(initializer, initargs),
    )
    restore = _interrupt_on_sigterm()
    try:
        yield pool
    except BaseException:
        stop(pool)
        raise
    finally:
        restore()
    pool.shutdown(wait=True)


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def _interrupt_on_sigterm() -> Callable[[], object]:
    """SIGTERM raises KeyboardInterrupt in the main thread (only it may set a handler; elsewhere nothing
    changes); returns what puts the previous handler back."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = signal.signal(signal.SIGTERM, _interrupt)  # None: one set outside Python, taken as the default
    return lambda: signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)


def stop(pool: ProcessPoolExecutor) -> None:
    """Cancel what has not started and terminate the workers (what has started is abandoned)."""
    processes = list((getattr(pool, "_processes", None) or {}).values())  # the stdlib has no public handle
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=5)
