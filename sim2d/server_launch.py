"""Run a SimServer: in the foreground until SIGINT/SIGTERM (`vtr sim serve`, :func:`serve`), or in the background,
a daemon thread (tests, notebooks) or a spawned child process that can be terminated or killed (crash tests,
benchmarks)."""

from __future__ import annotations

import multiprocessing
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from vtr.sim2d.server_config import ServerConfig

if TYPE_CHECKING:
    from vtr.sim2d.server import SimServer


def _sim_server(simulator: Any, cfg: ServerConfig) -> SimServer:
    # imported here: sim2d.server re-exports this module's names, so a top-level import would be circular
    from vtr.sim2d.server import SimServer

    return SimServer(simulator, cfg)


class ServerThread:
    """Run a SimServer in a daemon thread (tests, notebooks). Use as a context manager."""

    def __init__(self, simulator: Any, cfg: ServerConfig | None = None) -> None:
        self.server = _sim_server(simulator, cfg or ServerConfig(bind="tcp://127.0.0.1:*"))
        self._thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    def start(self, timeout: float = 10.0) -> ServerThread:
        self._thread.start()
        self.server.wait_ready(timeout)
        return self

    @property
    def endpoint(self) -> str:
        assert self.server.endpoint is not None
        return self.server.endpoint

    def stop(self, timeout: float = 5.0) -> None:
        self.server.stop()
        self._thread.join(timeout)

    def __enter__(self) -> ServerThread:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _process_main(cfg: ServerConfig, factory: Callable[[], Any] | None, conn: Any) -> None:
    simulator = factory() if factory is not None else None
    if simulator is None:
        from vtr.sim2d import SimConfig, Simulator  # type: ignore[attr-defined]

        simulator = Simulator(cfg.sim if cfg.sim is not None else SimConfig())
        simulator.reset()
    server = _sim_server(simulator, cfg)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: server.stop())
    threading.Thread(target=lambda: conn.send(server.wait_ready()), daemon=True).start()
    server.serve_forever()


@dataclass
class ServerProcess:
    """A server running in a child process; ``endpoint`` is where it listens."""

    process: Any
    endpoint: str
    _closed: bool = field(default=False, repr=False)

    def terminate(self, timeout: float = 5.0) -> int | None:
        """SIGTERM (clean shutdown), then SIGKILL if it does not exit; returns the exit code."""
        if self.process.is_alive():
            self.process.terminate()
            self.process.join(timeout)
        if self.process.is_alive():
            self.process.kill()
            self.process.join(timeout)
        return self.process.exitcode

    def kill(self, timeout: float = 5.0) -> int | None:
        """SIGKILL: the server dies without closing anything (a crash)."""
        if self.process.is_alive():
            self.process.kill()
            self.process.join(timeout)
        return self.process.exitcode

    def __enter__(self) -> ServerProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.terminate()


def start_server_process(
    cfg: ServerConfig, simulator_factory: Callable[[], Any] | None = None, timeout: float = 30.0
) -> ServerProcess:
    """Start a server in a fresh (spawned) process and wait until it listens.

    ``simulator_factory`` must be picklable (a module-level function); None builds
    ``sim2d.Simulator(cfg.sim)``. ``cfg.bind`` may use port ``*``: the real endpoint is returned.
    """
    ctx = multiprocessing.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    process = ctx.Process(target=_process_main, args=(cfg, simulator_factory, child), daemon=True)
    process.start()
    child.close()
    deadline = time.monotonic() + timeout
    while not parent.poll(0.1):
        if not process.is_alive() or time.monotonic() > deadline:
            process.kill()
            process.join(1.0)
            raise RuntimeError(f"simulator server did not start on {cfg.bind} (exit code {process.exitcode})")
    return ServerProcess(process=process, endpoint=parent.recv())


def serve(cfg: ServerConfig, simulator: Any = None) -> int:
    """`vtr sim serve`: build the simulator (unless given), serve until SIGINT/SIGTERM, return 0."""
    if simulator is None:
        from vtr.sim2d import SimConfig, Simulator  # type: ignore[attr-defined]  # pymunk lives behind this

        simulator = Simulator(cfg.sim if cfg.sim is not None else SimConfig())
        simulator.reset()
    server = _sim_server(simulator, cfg)
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, lambda *_: server.stop())
    try:
        thread = threading.Thread(target=_announce, args=(server,), daemon=True)
        thread.start()
        server.serve_forever()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    print(f"vtr sim serve: stopped after {server.requests} requests ({server.errors} refused)", flush=True)
    return 0


def _announce(server: SimServer) -> None:
    try:
        endpoint = server.wait_ready()
    except TimeoutError:
        return
    print(f"vtr sim serve: listening on {endpoint} (session {server.session}, {server.cfg.mode})", flush=True)
