"""`vtr collect` stopped by SIGTERM (`kill PID`, a job scheduler, a CI timeout) stops its workers too
(training/pool.py): before, the parent died at once and its forked workers recorded on, orphaned, each holding
the pool's call queue open so that none ever saw the parent go."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from tests.process_tree import children, running

ROOT = Path(__file__).resolve().parents[2]


def test_sigterm_stops_vtr_collect_and_its_workers(tmp_path: Path) -> None:
    args = [
        "collect",
        "--houses",
        "4",
        "--frames-per-house",
        "20000",
        "--workers",
        "2",
        "--out",
        str(tmp_path),
    ]
    proc = subprocess.Popen(
        [sys.executable, "-m", "vtr.cli", *args, "--no-progress"],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 60
        while len(children(proc.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.1)
        workers = children(proc.pid)
        time.sleep(2.0 if workers else 8.0)  # the workers are into their houses
        os.kill(proc.pid, signal.SIGTERM)  # the parent alone
        _, err = proc.communicate(timeout=30)
    finally:
        try:  # whatever is left of its process group, orphaned workers included
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert proc.returncode == 130 and err.strip().splitlines()[-1] == "vtr collect: interrupted", err
    time.sleep(0.2)
    assert not [pid for pid in workers if running(pid)], "workers still running"
