"""studies/side_registration_heights.py on one dev house, a few views."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from studies import side_registration_heights as study


def test_one_house_reports_the_estimates_against_the_truth(tmp_path: Path) -> None:
    out = tmp_path / "side.json"
    assert study.main(["--houses", "900:901", "--heights", "0.3", "--every", "12", "--json", str(out)]) == 0
    (row,) = json.loads(out.read_text())
    assert row["camera"] == [90.0, 0.3] and row["told"] + row["untold"] > 0
    if row["told"]:
        assert 0 <= row["dy_error_median_mm"] <= row["dy_error_p90_mm"] and 0 <= row["share_over_30mm"] <= 1


def test_held_out_houses_are_refused() -> None:
    with pytest.raises(SystemExit):
        study.main(["--houses", "5980:5981"])
