"""The GPU lease's script: chains run in order, a failed link stops its chain, the budget ends what is left,
and the packed runs come back in parts that join to the original bytes."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from studies.train_on_gpu import Session, run_parallel, split_file


def _session(tmp_path: Path, budget_s: float) -> Session:
    return Session(out=tmp_path / "out", work=tmp_path / "work", budget_s=budget_s, tiny=True, device="cpu")


def test_chains_run_in_order_and_a_failure_stops_its_chain(tmp_path: Path) -> None:
    s = _session(tmp_path, 60)
    s.out.mkdir()
    mark = tmp_path / "order.txt"
    py = sys.executable

    def write(text: str) -> list[str]:
        return [py, "-c", f"open({str(mark)!r}, 'a').write({text!r})"]

    run_parallel(
        s, {"a": [write("1"), write("2")], "b": [[py, "-c", "raise SystemExit(3)"], write("x")]}, "t"
    )
    assert mark.read_text() == "12"  # b's second link never ran
    rcs = {(r["job"], r["rc"]) for r in s.records}
    assert rcs == {("a", 0), ("b", 3)}
    assert (s.out / "summary.json").is_file() and "t/b: rc 3" in (s.out / "log.txt").read_text()


def test_the_budget_ends_what_is_still_running(tmp_path: Path) -> None:
    s = _session(tmp_path, 6)  # run_parallel kills a job once under 5 s are left
    s.out.mkdir()
    t0 = time.monotonic()
    run_parallel(s, {"slow": [[sys.executable, "-c", "import time; time.sleep(60)"]]}, "t")
    assert time.monotonic() - t0 < 30
    assert s.records[0]["rc"] != 0


def test_parts_join_to_the_packed_file(tmp_path: Path) -> None:
    data = bytes(range(256)) * 41  # 10,496 bytes
    src = tmp_path / "runs.tgz"
    src.write_bytes(data)
    parts = split_file(src, tmp_path, 4096)
    assert [p.name for p in parts] == ["part_00", "part_01", "part_02"]
    assert all(p.stat().st_size <= 4096 for p in parts)
    assert b"".join(p.read_bytes() for p in parts) == data
