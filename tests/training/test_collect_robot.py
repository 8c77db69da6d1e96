"""`vtr collect --sim`: a dataset from any protocol robot, safe with only `collided`, resumable, crash-safe."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from vtr import cli
from vtr.runtime.contracts import CameraSpec
from vtr.runtime.hello import Hello
from vtr.runtime.protocol import Limits
from vtr.runtime.robot import Observation, RobotError
from vtr.sim2d import SimConfig, Simulator
from vtr.sim2d.server import ServerThread
from vtr.training.collect_robot import COMMAND_MIX, ExplorationDriver, RobotCollectConfig, collect
from vtr.training.dataset import load_dataset


class CorridorRobot:
    """A robot in a 1-D corridor x in [0, 1]: a step that would leave it collides and does not move it."""

    def __init__(self, can_reset: bool = True, fail_after: int | None = None) -> None:
        self.x, self.yaw, self.t = 0.5, 0.0, 0.0
        self.can_reset, self.fail_after = can_reset, fail_after
        self.steps: list[tuple[float, float, bool]] = []
        self.resets: list[tuple | None] = []
        self.stopped = 0

    def _obs(self, collided: bool = False) -> Observation:
        image = np.full((8, 8, 3), int(self.x * 200) + int(self.yaw * 10) % 50, np.uint8)
        return Observation(image, self.t, (self.x, 0.0, self.yaw), collided)

    def handshake(self, width: int = 8) -> Hello:
        camera = CameraSpec(width=width, height=width, fov_deg=None, height_m=None)
        return Hello(
            "s1", 0.0, 1, camera, Limits(v_max=2.0, w_max=0.6), dt=0.1, mode="lockstep", map="corridor"
        )

    def reset(self, pose: tuple | None = None, seed: int | None = None) -> Observation:
        if not self.can_reset:
            raise RobotError("reset is not supported by this robot")
        self.x, self.yaw = (pose[0], pose[2]) if pose else (0.5, 0.0)
        self.resets.append(pose)
        return self._obs()

    def observe(self) -> Observation:
        return self._obs()

    def step(self, v: float, w: float, duration: float) -> Observation:
        if self.fail_after is not None and len(self.steps) >= self.fail_after:
            raise RobotError("robot went away")
        x = self.x + v * duration * math.cos(self.yaw)
        collided = not 0.0 <= x <= 1.0
        self.steps.append((v, w, collided))
        if not collided:
            self.x = x
        self.yaw += w * duration
        self.t += duration
        return self._obs(collided)

    def stop(self) -> None:
        self.stopped += 1


def config(tmp_path: Path, frames: int, **kw: object) -> RobotCollectConfig:
    return RobotCollectConfig(
        sim="tcp://127.0.0.1:9", out=str(tmp_path / "d"), frames=frames, progress=False, **kw
    )


def test_collected_from_our_simulator_over_the_wire(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = Simulator(SimConfig())
    sim.reset()
    out = tmp_path / "house"
    with ServerThread(sim) as server:
        code = cli.main(
            ["collect", "--sim", server.endpoint, "--out", str(out), "--frames", "300", "--no-progress"]
        )
    assert code == 0
    data = load_dataset(out, image_size=128)
    assert len(data) == 300 and data.meta["source"] == "vtr collect --sim" and data.meta["dt"] == 0.1
    assert data.meta["camera"]["fov_deg"] == 90.0
    assert np.abs(data.commands[:, 0]).max() <= 0.5 and np.abs(data.commands[:, 1]).max() <= 1.0
    # a recorded command moves its frame to the next one: replaying them from the poses matches (no noise)
    t = next(i for i in range(299) if data.episodes[i] == data.episodes[i + 1] and data.commands[i, 0] > 0.1)
    assert np.hypot(*(data.poses[t + 1, :2] - data.poses[t, :2])) > 0.005
    assert '"added": 300' in capsys.readouterr().out


def test_collisions_are_never_recorded_as_pairs_and_the_robot_backs_off(tmp_path: Path) -> None:
    robot = CorridorRobot()
    summary = collect(config(tmp_path, 600, seed=3), robot)
    data = load_dataset(tmp_path / "d")
    assert summary["counts"]["collisions"] > 0
    # limits: the robot's v_max (2.0) is capped at the model's 0.5; its w_max (0.6) is kept
    assert np.abs(data.commands[:, 0]).max() <= 0.5 and np.abs(data.commands[:, 1]).max() <= 0.6 + 1e-6
    hits = [i for i, (_, _, c) in enumerate(robot.steps) if c]
    for i in hits[:5]:  # after a hit: reverse first
        assert robot.steps[i + 1][0] < 0
    # no recorded pair spans a collision: every frame before a collided step ends its episode
    collided_frames = {k for k, (_, _, c) in enumerate(robot.steps) if c}
    for k in collided_frames:
        assert tuple(data.commands[k]) == (0.0, 0.0)
        assert data.episodes[k + 1] == data.episodes[k] + 1
    kinds = set(summary["counts"])
    assert {name for name, _ in COMMAND_MIX} - {"stop"} <= kinds
    assert robot.stopped >= 1


def test_a_robot_without_reset_drives_continuously(tmp_path: Path) -> None:
    robot = CorridorRobot(can_reset=False)
    summary = collect(config(tmp_path, 200, reset_every=1), robot)
    assert summary["reset"] is False and "resets" not in summary["counts"]
    assert summary["frames"] == 200


def test_resume_appends_episodes(tmp_path: Path) -> None:
    collect(config(tmp_path, 150), CorridorRobot())
    first = load_dataset(tmp_path / "d")
    summary = collect(config(tmp_path, 400), CorridorRobot())
    both = load_dataset(tmp_path / "d")
    assert summary["added"] == 250 and len(both) == 400
    np.testing.assert_array_equal(both.images[:150], first.images)
    assert both.episodes[150] == first.episodes.max() + 1
    assert collect(config(tmp_path, 300), CorridorRobot())["added"] == 0  # already has enough


def test_a_robot_lost_mid_run_leaves_what_was_recorded(tmp_path: Path) -> None:
    with pytest.raises(RobotError):
        collect(config(tmp_path, 500, save_every=10_000), CorridorRobot(fail_after=120))
    data = load_dataset(tmp_path / "d")
    assert len(data) == 121 and tuple(data.commands[-1]) == (0.0, 0.0)


def test_resume_refuses_another_camera(tmp_path: Path) -> None:
    collect(config(tmp_path, 50), CorridorRobot())
    robot = CorridorRobot()
    robot.handshake = lambda: CorridorRobot.handshake(robot, width=16)  # type: ignore[method-assign]
    with pytest.raises(ValueError, match="8x8 images, the robot's are 16x16"):
        collect(config(tmp_path, 100), robot)


def test_driver_respects_limits_and_backs_off() -> None:
    cfg = RobotCollectConfig(sim="tcp://x:1")
    driver = ExplorationDriver(np.random.default_rng(0), 0.3, 0.7, cfg)
    commands = [driver.next() for _ in range(2000)]
    assert max(abs(v) for _, v, _ in commands) <= 0.3 and max(abs(w) for _, _, w in commands) <= 0.7
    driver.collided(turn_rad=math.pi)
    escape = [driver.next() for _ in range(cfg.backoff_steps)]
    assert all(kind == "escape" and v < 0 for kind, v, _ in escape)
    turn = [driver.next() for _ in range(round(math.pi / (0.8 * 0.7 * cfg.dt)))]
    assert all(v == 0 and w != 0 for _, v, w in turn)


def test_a_camera_that_is_not_square_is_refused_before_driving(tmp_path: Path) -> None:
    robot = CorridorRobot()
    robot._obs = lambda collided=False: Observation(np.zeros((6, 8, 3), np.uint8), 0.0)  # type: ignore[method-assign]
    with pytest.raises(ValueError, match="images are 8x6; datasets hold square images"):
        collect(config(tmp_path, 50), robot)
    assert robot.steps == [] and not (tmp_path / "d").exists()


def test_around_starts_every_episode_along_the_taught_routes(tmp_path: Path) -> None:
    from vtr.runtime.route import Route

    route = tmp_path / "r.npz"
    poses = [(0.1, 0.0, 0.0), (0.9, 0.0, math.pi), (float("nan"),) * 3]  # an unknown pose is never used
    Route(np.zeros((3, 8, 8, 3), np.uint8), poses, np.zeros((3, 2))).save(route)
    robot = CorridorRobot()
    summary = collect(config(tmp_path, 400, seed=2, around=(str(route),)), robot)
    starts = np.array(robot.resets)
    assert summary["counts"]["resets"] == summary["episodes"] - 1 and len(starts) == summary["episodes"]
    assert set(np.round(starts[:, 0], 6)) == {0.1, 0.9}
    yaw_offset = np.where(
        starts[:, 0] < 0.5, starts[:, 2], (starts[:, 2] - math.pi + math.pi) % (2 * math.pi) - math.pi
    )
    assert np.abs(yaw_offset).max() <= math.radians(35) and np.abs(yaw_offset).max() > 0.05
    assert load_dataset(tmp_path / "d").meta["around"] == [str(route)]
    no_reset = CorridorRobot(can_reset=False)
    with pytest.raises(RobotError, match="reset is not supported"):  # --around needs reset with a pose
        collect(config(tmp_path / "x", 50, around=(str(route),)), no_reset)
