"""studies/floor_probe.py on a tiny stand-in model, a few pairs of one dev route."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from studies import floor_probe


def test_a_few_pairs_report_the_change_per_scene(tiny: tuple[str, str], tmp_path: Path) -> None:
    out = tmp_path / "probe.json"
    argv = ["--model", tiny[0], "--pairs", "3", "--route-seeds", "100:101", "--json", str(out)]
    assert floor_probe.main(argv) == 0
    row = json.loads(out.read_text())[tiny[0]]
    assert set(row) >= {"dv_rms_floor_recoloured", "dw_rms_wall_retextured", "w_rms_taught"}
    assert all(v >= 0 for k, v in row.items() if "rms" in k)


def test_held_out_route_seeds_are_refused(tiny: tuple[str, str]) -> None:
    with pytest.raises(SystemExit):
        floor_probe.main(["--model", tiny[0], "--route-seeds", "1300:1301"])
