"""Ctrl-C in `vtr eval` stops it at once (its process pool, training/pool.py): exit 130, one
line, no worker left running. Before the pool stopped its workers this took 16 s on 2 cores."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from tests.process_tree import children, running

ROOT = Path(__file__).resolve().parents[2]
#: more routes than workers: a pool that is not stopped goes on with the queued ones
# long enough that the eval is still running when the interrupt comes (the repeat now runs at the taught pace)
ROUTES = (
    "grand_tour",
    "living_circle",
    "translation_rotation",
    "kitchen_to_office",
    "living_to_study",
    "bedroom_to_study",
)


def test_ctrl_c_stops_vtr_eval_and_its_workers_at_once(tmp_path: Path) -> None:
    _stop_and_check(tmp_path, to_group=True)


def test_sigterm_to_vtr_eval_alone_stops_its_workers_too(tmp_path: Path) -> None:
    """`kill PID` (a job scheduler, a CI timeout, `pkill -f`) signals the parent only: it died at once and its
    spawned workers lived on, idle, holding their memory (three found 50 minutes later in session 13)."""
    _stop_and_check(tmp_path, to_group=False)


def _stop_and_check(tmp_path: Path, to_group: bool) -> None:
    """Start `vtr eval` on two workers, stop it (SIGINT to its process group, as Ctrl-C; or SIGTERM to the
    parent alone) once the workers are into their routes, and check it ended at once, in one line, with no
    worker left."""
    out = tmp_path / "eval.json"
    args = ["eval", "--routes", *ROUTES, "--workers", "2", "--json", str(out)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "vtr.cli", *args],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        start_new_session=True,  # its own process group, as a terminal's foreground job
        # an earlier test of this process may leave SIGINT ignored, and an ignored signal is inherited
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + 60
        while len(children(proc.pid)) < 3 and time.monotonic() < deadline:  # 2 workers + the resource tracker
            time.sleep(0.1)
        workers = children(proc.pid)
        time.sleep(3.0 if workers else 8.0)  # the workers are into their routes
        if to_group:
            os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C: the whole group, workers included
        else:
            os.kill(proc.pid, signal.SIGTERM)  # the parent alone
        t0 = time.monotonic()
        _, err = proc.communicate(timeout=60)
        stopped_s = time.monotonic() - t0
    finally:
        try:  # whatever is left of its process group, orphaned workers included
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert "Traceback" not in err, err
    assert proc.returncode == 130 and err.strip().splitlines()[-1] == "vtr eval: interrupted"
    assert stopped_s < 3.0, f"took {stopped_s:.1f} s to stop"
    assert not out.exists()
    time.sleep(0.2)
    alive = [pid for pid in workers if running(pid)]
    assert not alive, f"workers still running: {alive}"
