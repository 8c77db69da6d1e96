"""trace_run: one suite run, step by step, with the unchanged house's error at the same true pose."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vtr.evaluation.trace_run import main, trace
from vtr.sim2d.routes import ROUTES_DIR

ROUTE = ROUTES_DIR / "translation.json"


def test_rows_follow_the_run_and_the_clean_error_equals_the_error_in_the_unchanged_house(tmp_path: Path):
    rows, end = trace(ROUTE, "noise_0.05", seed=0)
    assert rows and end.startswith("finished")
    # starts on the first taught pose, steering to the subgoal ahead of it (the follower's lead)
    assert rows[0]["nearest_mm"] == 0.0 and rows[0]["nearest_k"] == 0 and rows[0]["i"] <= 1
    # nothing changed but the actuation: the unchanged house at the true pose is the camera image
    np.testing.assert_allclose([r["clean_error"] for r in rows], [r["error"] for r in rows], atol=1e-6)
    assert max(r["i"] for r in rows) > 0
    rows, end = trace(ROUTE, "bright_0.7", seed=0)  # changed light: the view differs from the clean one
    assert any(abs(r["clean_error"] - r["error"]) > 1e-3 for r in rows)
    out = tmp_path / "t.json"
    assert main([str(ROUTE), "noise_0.05", "--every", "50", "--json", str(out)]) == 0 and out.is_file()
    assert main([str(ROUTE), "no_such_condition"]) == 2


def test_it_traces_the_follower_and_the_side_offset_it_sees():
    rows, end = trace(ROUTE, "offset_10cm_10deg", seed=0)
    assert rows[0]["cross_mm"] > 90  # started 10 cm to the left
    seen = [
        r for r in rows if np.isfinite(r["side_mm"])
    ]  # the follower's floor estimate (the rules have none)
    assert seen and abs(seen[0]["side_mm"] - seen[0]["cross_mm"]) < 30


def test_it_traces_where_the_localiser_placed_the_robot():
    """Each row carries the route localiser's estimate (position, confidence, the common offset), which
    tells a matching failure from a localisation one without a script of one's own around the localiser."""
    rows, end = trace(ROUTE, "noise_0.05", seed=0)
    positions = np.array([r["position"] for r in rows])
    assert np.isfinite(positions).all() and positions[-1] >= positions[0] + 10  # it moved along the route
    assert all(0.0 <= r["confidence"] <= 1.0 and r["match"] >= 0.0 for r in rows)
    near = [abs(r["position"] - r["nearest_k"]) for r in rows]
    assert np.median(near) <= 1.0  # placed within a gap of the nearest taught pose


def test_it_repeats_on_the_robot_the_suite_repeats_on(monkeypatch):
    """The trace built its own robot: no moving box, no box taken away, no sensor, the default camera, so a
    held-out run that touched the moving obstacle finished when traced. It now asks the suite's
    ``suite_robot``, with the condition's scene written, as ``run_once`` does."""
    from vtr.evaluation import condition_run
    from vtr.evaluation.moving_box import CrossingRobot

    made: list[object] = []
    real = condition_run.suite_robot

    def recording(*args):
        robot = real(*args)
        made.append(robot)
        return robot

    monkeypatch.setattr(condition_run, "suite_robot", recording)
    trace(ROUTE, "moving_obstacle", seed=0)
    assert len(made) == 1
    robot, clearing, crossing = made[0]
    assert isinstance(crossing, CrossingRobot) and clearing is None


def test_a_camera_given_is_the_robots_at_teach_and_at_repeat(monkeypatch):
    """`--camera FOV,HEIGHT` traces a run of `vtr eval --camera`: the route taught and repeated with that
    camera (the trace taught with the default camera even where the condition named another)."""
    from vtr.evaluation import condition_run, harness

    taught: list[object] = []
    repeated: list[object] = []
    real_teach, real_robot = harness.teach, condition_run.suite_robot

    def teach(*args, **kwargs):
        taught.append(kwargs.get("camera"))
        return real_teach(*args, **kwargs)

    def robot(route, cond, *args):
        repeated.append(cond.camera)
        return real_robot(route, cond, *args)

    monkeypatch.setattr(harness, "teach", teach)
    monkeypatch.setattr(condition_run, "suite_robot", robot)
    rows, _ = trace(ROUTE, "noise_0.05", seed=0, camera=(65.0, 0.3))
    assert rows and taught == [(65.0, 0.3)] and repeated == [(65.0, 0.3)]
    assert main([str(ROUTE), "noise_0.05", "--camera", "65,0.3", "--every", "500"]) == 0
    assert taught[-1] == (65.0, 0.3)
