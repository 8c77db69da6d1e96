"""Metrics against hand-computed examples."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vtr.evaluation import metrics


def test_nearest_point_errors_hand_computed() -> None:
    taught = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    repeated = np.array([[0.0, 0.3], [1.1, 0.0], [5.0, 5.0]])
    err = metrics.nearest_point_errors(taught, repeated)
    # (0,0)->(0,0.3): 0.3; (1,0)->(1.1,0): 0.1; (2,0)->(1.1,0): 0.9
    np.testing.assert_allclose(err, [0.3, 0.1, 0.9])
    stats = metrics.error_stats(err)
    assert stats["min"] == pytest.approx(0.1)
    assert stats["max"] == pytest.approx(0.9)
    assert stats["mean"] == pytest.approx(1.3 / 3)
    # population std of (0.3, 0.1, 0.9)
    assert stats["std"] == pytest.approx(
        math.sqrt(((0.3 - 1.3 / 3) ** 2 + (0.1 - 1.3 / 3) ** 2 + (0.9 - 1.3 / 3) ** 2) / 3)
    )
    assert stats["n"] == 3


def test_nearest_yaw_errors_wrap_around() -> None:
    taught = np.radians([179.0, -90.0, 0.0])
    repeated = np.radians([-179.0, -80.0, 3.0])
    err = metrics.nearest_yaw_errors(taught, repeated)
    # 179 vs -179 is 2 degrees across the wrap, not 358
    np.testing.assert_allclose(err, [2.0, 10.0, 3.0], atol=1e-9)


def test_final_pose_error() -> None:
    out = metrics.final_pose_error((1.0, 2.0, math.radians(170)), (4.0, 6.0, math.radians(-170)))
    assert out["position_m"] == pytest.approx(5.0)
    assert out["yaw_deg"] == pytest.approx(20.0)


def test_cross_track_to_polyline() -> None:
    line = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    pts = np.array([[1.0, 0.5], [3.0, 1.0], [-1.0, 0.0], [2.0, 3.0]])
    d = metrics.point_to_polyline_distances(pts, line)
    # above the first segment; right of the second; behind the start; beyond the end
    np.testing.assert_allclose(d, [0.5, 1.0, 1.0, 1.0])
    assert metrics.mean_cross_track_error(pts, line) == pytest.approx(0.875)


def test_cross_track_degenerate_segments() -> None:
    line = np.array([[0.0, 0.0], [0.0, 0.0]])
    d = metrics.point_to_polyline_distances(np.array([[3.0, 4.0]]), line)
    np.testing.assert_allclose(d, [5.0])
    d1 = metrics.point_to_polyline_distances(np.array([[3.0, 4.0]]), line[:1])
    np.testing.assert_allclose(d1, [5.0])


def test_smoothness_and_completion() -> None:
    cmds = np.array([[0.1, 0.0], [0.3, -0.5], [0.2, 0.5]])
    s = metrics.smoothness(cmds)
    assert s["mean_abs_dv"] == pytest.approx((0.2 + 0.1) / 2)
    assert s["mean_abs_dw"] == pytest.approx((0.5 + 1.0) / 2)
    assert metrics.smoothness(cmds[:1]) == {"mean_abs_dv": 0.0, "mean_abs_dw": 0.0}
    assert metrics.completion(3, 4) == 0.75
    with pytest.raises(ValueError, match="5"):
        metrics.completion(5, 4)


def test_route_metrics_identity_run_is_perfect() -> None:
    t = np.linspace(0, 1, 11)
    taught = np.stack([t, 0.5 * t, 0.2 * t], axis=1)
    out = metrics.route_metrics(taught, taught.copy(), np.zeros((5, 2)), subgoals_reached=11)
    assert out["position_error_m"]["max"] == 0.0
    assert out["yaw_error_deg"]["max"] == 0.0
    assert out["completed"] is True
    assert out["mean_cross_track_error_m"] == pytest.approx(0.0, abs=1e-12)
    assert out["rotation_only"] is False
    rot = np.stack([np.zeros(5), np.zeros(5), np.linspace(0, 3, 5)], axis=1)
    assert metrics.route_metrics(rot, rot, np.zeros((0, 2)), 2)["rotation_only"] is True


def test_bad_shapes_raise() -> None:
    with pytest.raises(ValueError, match="shape"):
        metrics.nearest_point_errors(np.zeros(3), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="empty"):
        metrics.nearest_point_errors(np.zeros((0, 2)), np.zeros((2, 2)))


def test_densify_path_interpolates_and_wraps_yaw() -> None:
    poses = np.array([[0.0, 0.0, math.radians(170)], [1.0, 2.0, math.radians(-170)]])
    dense = metrics.densify_path(poses, 4)
    assert dense.shape == (5, 3)
    np.testing.assert_allclose(dense[:, 0], [0.0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(dense[:, 1], [0.0, 0.5, 1.0, 1.5, 2.0])
    # 170 -> -170 deg goes the short way through 180, not back through 0
    np.testing.assert_allclose(np.degrees(metrics.wrap_angle(dense[2, 2] - math.pi)), 0.0, atol=1e-9)
    np.testing.assert_allclose(metrics.densify_path(poses, 1), poses)


def test_route_metrics_paper_errors_are_step_sampled_path_errors_are_continuous() -> None:
    # taught points halfway between the repeated step poses: the path passes through them,
    # the poses sampled at each command (the paper's red dots) miss them by half a step
    taught = np.array([[0.05, 0.0, 0.0], [0.15, 0.0, 0.0]])
    repeated = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.2, 0.0, 0.0]])
    out = metrics.route_metrics(taught, repeated, np.zeros((2, 2)), 2, per_step=10)
    assert out["position_error_m"]["max"] == pytest.approx(0.05)
    assert out["path_position_error_m"]["max"] == pytest.approx(0.0, abs=1e-12)
