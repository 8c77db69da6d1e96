"""studies.step_stages runs the taught step with every stage timed and prints p50 / p99 per stage."""

from __future__ import annotations

from pathlib import Path

import pytest

from studies import step_stages

MODEL = Path(__file__).resolve().parents[2] / "models" / "velocitynet.onnx"


def test_every_stage_gets_a_row(capsys: pytest.CaptureFixture[str]) -> None:
    assert step_stages.main([str(MODEL), "--steps", "4", "--warmup", "1"]) == 0
    out = capsys.readouterr().out
    for stage in ("predict.inference", "predict.preprocess"):
        assert stage in out
    rows = [line.split() for line in out.splitlines()[1:] if line.strip()]
    assert rows and all(float(r[-1]) >= float(r[-2]) >= 0 for r in rows)  # p99 >= p50 >= 0 on every row
