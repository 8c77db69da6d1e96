"""studies/camera_sizes.py on one short route at one camera size: taught and repeated through the resampling."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from studies import camera_sizes


def test_a_4_3_camera_sees_90_deg_in_its_square_centre() -> None:
    assert camera_sizes.fov_for(160, 120) == pytest.approx(2 * math.degrees(math.atan(4 / 3)))
    assert camera_sizes.fov_for(128, 128) == pytest.approx(90.0)


def test_one_route_at_160x120(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    script = tmp_path / "short.json"
    segments = [{"v": 0.25, "w": 0.0, "duration": 1.5}]
    script.write_text(json.dumps({"start": {"x": 2.0, "y": 3.0, "yaw": 0.0}, "segments": segments}))
    out = tmp_path / "rows.json"
    argv = [
        "--sizes",
        "160x120",
        "--route-seeds",
        "--routes",
        str(script),
        "--noise",
        "0",
        "--json",
        str(out),
    ]
    assert camera_sizes.main(argv) == 0
    assert "| 160x120 | 1/1 |" in capsys.readouterr().out
    (row,) = json.loads(out.read_text())["rows"]
    assert row["status"] == "finished" and row["resample_ms"] > 0
