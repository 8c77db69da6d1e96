"""The step profiler and the two-version A/B script, on a tiny stand-in model (no timing assertions)."""

from __future__ import annotations

from pathlib import Path

import pytest

from vtr.benchmarks.standin import make_standin_velocitynet
from vtr.runtime.model_meta import ModelMeta

TINY = ModelMeta(image_height=32, image_width=32, horizon=2)
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, str]:
    from vtr.benchmarks.step_bench_ab import write_route

    folder = tmp_path_factory.mktemp("m")
    model = str(make_standin_velocitynet(folder / "tiny.onnx", meta=TINY, widths=(4, 8)))
    route = str(folder / "route.npz")
    write_route(route, model)
    return model, route


def test_the_profiler_times_each_stage_inside_its_parent_and_unwraps_afterwards(
    tiny: tuple[str, str],
) -> None:
    from vtr.benchmarks import step_profile
    from vtr.benchmarks.step_bench_ab import _repeaters
    from vtr.runtime import light, matching

    model, route = tiny
    rep = _repeaters(route, model)["light"]
    stages = step_profile.profile_stages(rep, steps=5, warmup=1)
    us = {k: v["median_us"] for k, v in stages.items()}
    assert us["step"] > us["predict"] > us["predict.inference"] > 0
    assert us["judge"] >= us["judge.features"] >= us["judge.features.normalise"] > 0
    assert us["predict.light_match"] >= us["predict.light_match.ramp"] > 0
    assert stages["link.decode_reply"]["calls_per_step"] == 2  # the step's reply and the zero command's
    # everything wrapped is itself again: instance attributes removed, module functions put back
    assert "predict" not in vars(rep.policy) and "step" not in vars(rep.robot)
    assert matching.planar_levels.__module__ == "vtr.runtime.preprocess"
    assert light._ramp.__name__ == "_ramp" and rep.step().commanded
    assert "cumtime" in step_profile.cprofile_top(rep, steps=3, warmup=1, top=5)


def test_the_version_ab_steps_each_variant_of_both_checkouts(tiny: tuple[str, str]) -> None:
    from vtr.benchmarks import step_bench_versions

    model, route = tiny
    out = step_bench_versions.medians(ROOT, route, model, steps=3, warmup=1)
    assert set(out) == {"raw", "patch", "light"}
    assert all(v["base_us"] > 0 and v["new_us"] > 0 for v in out.values())
