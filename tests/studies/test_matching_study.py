"""The matching study (studies/matching_study.py) on one tuning route, every 12th subgoal."""

from __future__ import annotations

from studies.matching_study import METHODS, TUNING_ROUTES, study


def test_the_study_looks_only_at_tuning_routes():
    from vtr.sim2d.routes import list_routes

    assert set(TUNING_ROUTES) <= set(list_routes())  # sim2d/routes: never a held-out set


def test_matching_study_shows_patch_matching_ignores_light_where_the_raw_error_does_not():
    result = study(("kitchen_arc",), 12, {m: METHODS[m] for m in ("raw", "patch_median")})
    raw, patch = result["raw"], result["patch_median"]
    assert raw["clean"]["at_pose"] == 0.0 and patch["clean"]["at_pose"] == 0.0
    assert raw["bright_0.6"]["switchable"] == 0.0 and patch["bright_0.6"]["switchable"] == 1.0
    assert patch["bright_0.6"]["at_pose"] < 0.2 < 1.0 < raw["bright_0.6"]["at_pose"]
    assert patch["clean"]["along_0.1"] > patch["clean"]["along_0.02"] > patch["clean"]["at_pose"]
