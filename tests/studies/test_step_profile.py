"""The step profiler (studies/step_profile.py) on a tiny stand-in model (no timing assertions)."""

from __future__ import annotations

import pytest

from studies import step_bench_ab, step_profile


def test_the_profiler_times_each_stage_inside_its_parent_and_unwraps_afterwards(
    tiny: tuple[str, str],
) -> None:
    from vtr.runtime import frame, light

    model, route = tiny
    rep = step_bench_ab._repeaters(route, model)["light"]
    stages = step_profile.profile_stages(rep, steps=5, warmup=1)
    us = {k: v["median_us"] for k, v in stages.items()}
    assert us["step"] > us["predict"] > us["predict.inference"] > 0
    assert us["judge"] >= us["judge.features"] >= us["judge.features.normalise"] > 0
    assert us["predict.light_match"] >= us["predict.light_match.ramp"] > 0
    assert stages["link.decode_reply"]["calls_per_step"] == 2  # the step's reply and the zero command's
    # everything wrapped is itself again: instance attributes removed, module functions put back
    assert "predict" not in vars(rep.policy) and "step" not in vars(rep.robot)
    assert frame.planar.__module__ == "vtr.runtime.frame" and frame.planar.__name__ == "planar"
    assert light._ramp.__name__ == "_ramp" and rep.step().commanded
    assert "cumtime" in step_profile.cprofile_top(rep, steps=3, warmup=1, top=5)


def test_the_profiler_runs_from_the_command_line(
    tiny: tuple[str, str], capsys: pytest.CaptureFixture
) -> None:
    model, route = tiny
    assert step_profile.main([model, "--route", route, "--steps", "3", "--warmup", "1"]) == 0
    assert "predict.inference" in capsys.readouterr().out
