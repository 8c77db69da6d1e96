"""Repeat-time conditions and the condition suite (`vtr eval --suite conditions`) on a tiny stand-in model."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from vtr.benchmarks.standin import make_standin_velocitynet
from vtr.evaluation import condition_suite as suite
from vtr.evaluation.condition_run import start_pose
from vtr.evaluation.conditions import LIGHTING, SCENES, LitRobot, brightness, side_darker, write_scene_house
from vtr.runtime.model_meta import ModelMeta
from vtr.runtime.robot import Observation


def test_lighting_functions():
    img = np.full((4, 8, 3), 100, np.uint8)
    assert (brightness(1.5)(img) == 150).all() and (brightness(3.0)(img) == 255).all()
    dark = side_darker(0.5, "left")(img)
    assert dark[0, 0, 0] == 50 and dark[0, -1, 0] == 100
    assert side_darker(0.5, "right")(img)[0, -1, 0] == 50
    assert set(LIGHTING) >= {"bright_0.6", "bright_1.5", "colour_cast", "left_darker"}


class OneFrame:
    def __init__(self) -> None:
        self.stopped = False

    def reset(self, pose=None, seed=None) -> Observation:
        return self.observe()

    def observe(self) -> Observation:
        return Observation(np.full((4, 4, 3), 200, np.uint8), 0.0, (1.0, 2.0, 0.0), collided=True)

    def step(self, v: float, w: float, duration: float) -> Observation:
        return self.observe()

    def stop(self) -> None:
        self.stopped = True


def test_lit_robot_changes_only_the_image():
    robot = LitRobot(OneFrame(), brightness(0.5))
    for obs in (robot.reset(), robot.observe(), robot.step(0.1, 0.0, 0.1)):
        assert (obs.image == 100).all() and obs.pose == (1.0, 2.0, 0.0) and obs.collided
    robot.stop()
    assert robot.robot.stopped


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_scene_houses_load_and_differ(scene, tmp_path):
    from vtr.sim2d import Pose, SimConfig, Simulator

    path = write_scene_house(scene, tmp_path)
    pose = Pose(2.8, 3.0, math.pi)  # living room, looking at the sofa and the tv cabinet
    if scene == "wall_retextured":
        pose = Pose(3.0, 2.5, math.pi / 2)  # looking at the living room's north wall
    if scene == "floor_recoloured":
        pose = Pose(3.0, 2.5, 0.0)
    before = Simulator(SimConfig()).reset(pose=pose, seed=0)
    after = Simulator(SimConfig(house=str(path))).reset(pose=pose, seed=0)
    assert np.abs(before.astype(int) - after.astype(int)).mean() > 1.0
    with pytest.raises(ValueError, match="unknown scene"):
        write_scene_house("flooded", tmp_path)


def test_start_offsets_are_lateral_and_flip_with_the_seed():
    pose = np.array([1.0, 2.0, math.pi / 2])
    x, y, yaw = start_pose(pose, (0.1, 10.0), seed=0)
    assert (x, y) == pytest.approx((0.9, 2.0)) and yaw == pytest.approx(math.pi / 2 + math.radians(10))
    x, y, yaw = start_pose(pose, (0.1, 10.0), seed=1)
    assert (x, y) == pytest.approx((1.1, 2.0)) and yaw == pytest.approx(math.pi / 2 - math.radians(10))


@pytest.fixture(scope="module")
def small_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    meta = ModelMeta(image_height=32, image_width=32)
    return make_standin_velocitynet(tmp_path_factory.mktemp("m") / "tiny.onnx", meta=meta, widths=(8, 16, 16))


def test_suite_runs_every_combination_and_reports_per_condition(small_model, tmp_path):
    cfg = suite.SuiteConfig(
        model=small_model,
        routes=("ho_study_arc",),
        conditions=("noise_0.05", "bright_0.6"),
        seeds=(0, 1),
        controllers=("paper", "after"),
        models=("fp32",),
        workers=1,
        max_steps_factor=0.5,
        json_path=tmp_path / "suite.json",
    )
    result = suite.run(cfg)
    assert len(result["runs"]) == 2 * 2 * 2 and len(result["table"]) == 2 * 2
    for run in result["runs"]:
        assert run["ran"] and run["status"] in {"finished", "stalled", "lost", "collided", "step_limit"}
        assert run["completed"] == (run["status"] == "finished" and run["contacts"] == 0)
        assert run["completed"] or run["cause"]
    for row in result["table"]:
        assert row["runs"] == 2 and row["completed"] + sum(row["failure_causes"].values()) == 2
        # the real step's cost, per run: every commanded step timed (the link and the simulator apart)
        timed = run["step_compute_ms"]
        assert 0 < timed["p50"] <= timed["p99"] <= timed["max"]
    cost = result["step_compute"]
    assert cost["runs"] == len(result["runs"])
    assert cost["worst_p99"] == max(r["step_compute_ms"]["p99"] for r in result["runs"])
    assert cost["max"] == max(r["step_compute_ms"]["max"] for r in result["runs"])
    saved = json.loads((tmp_path / "suite.json").read_text())
    assert saved["routes"] == ["ho_study_arc"]
    md = (tmp_path / "suite.md").read_text()
    assert "| after | fp32 | bright_0.6 |" in md
    assert f"worst run's p99 {cost['worst_p99']:.2f} ms" in md and "1 worker(s)" in md


def test_suite_config_refuses_unknown_names(small_model):
    with pytest.raises(ValueError, match="condition"):
        suite.SuiteConfig(model=small_model, conditions=("fog",), models=("fp32",))
    with pytest.raises(ValueError, match="route not found"):
        suite.SuiteConfig(model=small_model, routes=("nowhere",), models=("fp32",))
    with pytest.raises(ValueError, match="int8"):
        suite.SuiteConfig(model=small_model, models=("int8",))


def test_heldout_routes_are_apart_from_the_tuning_routes():
    from vtr.sim2d.routes import list_routes

    heldout = {p.stem for p in suite.route_paths(())}
    second = {p.stem for p in suite.route_paths((str(suite.HELDOUT_DIR.with_name("heldout2")),))}
    assert len(heldout) == 8 and len(second) == 6 and not heldout & second
    assert not (heldout | second) & set(list_routes())  # tuning used only sim2d/routes


def test_a_box_is_placed_beside_the_path_clear_of_the_robot(tmp_path):
    from vtr.evaluation.conditions import BOX_GAP, BOX_SIDE, ROBOT_RADIUS
    from vtr.sim2d import load_house

    path = np.array([[2.0 + 0.05 * k, 3.0, 0.0] for k in range(30)])  # straight along +x in the living room
    house = load_house(write_scene_house("obstacle_beside_path", tmp_path, path=path))
    (box,) = [f for f in house.furniture if f.name == "box"]
    gap = np.hypot(path[:, 0] - box.center[0], path[:, 1] - box.center[1]).min()
    assert gap == pytest.approx(ROBOT_RADIUS + BOX_GAP + BOX_SIDE / 2)
    assert min(house.clearance(x, y) for x, y, _ in path) >= ROBOT_RADIUS + BOX_GAP - 1e-6
    with pytest.raises(ValueError, match="needs the taught path"):
        write_scene_house("obstacle_beside_path", tmp_path)


def test_comparison_table_puts_methods_side_by_side(tmp_path, capsys):
    from vtr.evaluation.condition_tables import main

    row = {
        "controller": "after",
        "model": "fp32",
        "condition": "bright_0.6",
        "completed": 2,
        "runs": 3,
        "mean_position_error_m": 0.0081,
        "steps_per_taught_step": 1.42,
    }
    other = dict(row, controller="paper", completed=0, mean_position_error_m=None, steps_per_taught_step=None)
    for name, r in (("a", row), ("b", other)):
        (tmp_path / f"{name}.json").write_text(json.dumps({"table": [r]}))
    assert main([str(tmp_path / "a.json"), str(tmp_path / "b.json")]) == 0
    out = capsys.readouterr().out
    assert (
        "| condition | after fp32 | paper fp32 |" in out
        and "| bright_0.6 | 2/3, 8.1 mm, 1.42x | 0/3, -, - |" in out
    )
    assert main([str(tmp_path / "missing.json")]) == 2


class Forward:
    """A policy that always drives forward while turning."""

    image_shape = (32, 32)
    nonfinite_count = 0

    def predict(self, current: np.ndarray, subgoal: np.ndarray) -> np.ndarray:
        return np.array([[0.3, 0.3], [0.5, 0.5]], dtype=np.float32)


def test_the_evaluation_loop_holds_taught_turns_in_place(tmp_path):
    from vtr.evaluation.harness import EvalConfig, make_robot, teach
    from vtr.evaluation.runs import repeat_closed_loop
    from vtr.runtime.controller import ControllerConfig

    script = {
        "name": "spin",
        "start": {"x": 2.8, "y": 3.0, "yaw": 0.0},
        "segments": [{"v": 0.0, "w": 0.5, "duration": 1.0}],
    }
    path = tmp_path / "spin.json"
    path.write_text(json.dumps(script))
    route, _ = teach(path, (32, 32), 0.1)
    cfg = EvalConfig(model=None, quick=True, workers=1)
    ccfg = ControllerConfig(e_m_mode="per_subgoal", pass_ratio=1.0)  # switches on while the robot turns
    log = repeat_closed_loop(make_robot(0.0, (32, 32)), Forward(), route, (2.8, 3.0, 0.0), cfg, 0, ccfg)
    assert log.commands and all(v == 0.0 for v, _ in log.commands[1:])  # subgoal 0 has no taught turn into it


def test_completed_runs_far_from_the_path_are_counted_beside_completion():
    base = {
        "controller": "after",
        "model": "fp32",
        "condition": "floor_recoloured",
        "ran": True,
        "contacts": 0,
        "position_error_m": 0.01,
        "yaw_error_deg": 0.1,
        "cross_track_m": 0.01,
        "final_position_m": 0.01,
        "final_yaw_deg": 0.1,
        "steps_per_taught_step": 1.5,
        "cause": "",
    }
    runs = [
        {**base, "completed": True, "max_position_error_m": 0.05},
        {**base, "completed": True, "max_position_error_m": 0.35},  # finished another path
        {**base, "completed": False, "max_position_error_m": 0.90, "cause": "stalled: x"},
    ]
    (row,) = suite.aggregate(runs)
    assert row["completed"] == 2 and row["completed_off_path"] == 1
    table = suite.markdown(
        {"config": {"seeds": [0], "max_steps_factor": 8.0}, "routes": ["r"], "table": [row]}
    )
    assert "| 2/3 (1 > 10 cm off the path) |" in table


def test_a_change_that_blocks_the_taught_path_is_refused_not_scored(tmp_path):
    import json

    from vtr.evaluation.conditions import ROBOT_RADIUS, PathBlocked, path_clearance
    from vtr.sim2d.house import resolve_house_path

    # along y = 1.9 just east of the coffee table (x 0.8-1.8): free now, inside it once it moves 30 cm east
    path = np.array([[2.1 + 0.05 * k, 1.9, 0.0] for k in range(6)])
    unchanged = json.loads(resolve_house_path("house").read_text())
    assert path_clearance(unchanged, path)[0] >= ROBOT_RADIUS
    with pytest.raises(PathBlocked, match="blocks the taught path"):
        write_scene_house("furniture_moved", tmp_path, path=path)
    assert write_scene_house("furniture_moved", tmp_path, path=path, allow_blocked=True).exists()
    assert write_scene_house("wall_retextured", tmp_path, path=path).exists()  # walls moved nowhere
