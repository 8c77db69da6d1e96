"""The paper-preset lease script: stages share the budget by their steps, and each stage starts from the last."""

from __future__ import annotations

from pathlib import Path

from studies.paper_preset_on_gpu import STAGES, chain, stage_minutes
from studies.train_on_gpu import Session


def test_stage_budgets_fit_the_time_and_follow_the_steps() -> None:
    minutes = stage_minutes(8.0)
    assert list(minutes) == [name for name, *_ in STAGES]
    assert sum(minutes.values()) <= 8.0
    assert minutes["floors"] > minutes["a"] > minutes["c"]  # the floor stage has the most (weighted) steps


def test_each_stage_starts_from_the_previous_one_at_the_recipe_settings(tmp_path: Path) -> None:
    s = Session(out=tmp_path / "o", work=tmp_path / "w", budget_s=600, tiny=False, device="cuda")
    cmds = chain(s, tmp_path / "data", "models/viewnet.pt", tmp_path / "runs", "paper", 1, "paper_s1")
    assert len(cmds) == len(STAGES)
    for k, (cmd, (stage, steps, lr, flags)) in enumerate(zip(cmds, STAGES, strict=True)):
        args = " ".join(cmd)
        assert f"--out {tmp_path / 'runs' / f'paper_s1_{stage}'}" in args
        assert f"--steps {steps} " in args and f"--lr {lr} " in args and "--preset paper" in args
        assert " ".join(flags) in args and "--seed 1 " in args and "--batch-size 64" in args
        if k:
            assert cmd[-2:] == [
                "--init",
                str(tmp_path / "runs" / f"paper_s1_{STAGES[k - 1][0]}" / "model.pt"),
            ]
        else:
            assert "--init" not in cmd
