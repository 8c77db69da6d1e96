"""ROS 2 bags in: bags written here with rosbags (MCAP and sqlite3, the `ros2 bag record` layout) become a drive at
dt, a training dataset (`vtr collect --bag`) and a route (`vtr teach --bag`), with every skipped frame explained."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from bag_fixtures import picture, write_drive_bag

from vtr import cli
from vtr.runtime.route import Route
from vtr.training.bag_read import BagError, read_bag
from vtr.training.dataset import load_dataset


def drive(path: Path, **kw: object) -> object:
    odom = kw.pop("odom_topic", "/odom")
    return read_bag([path], "/camera/image", "/cmd_vel", odom, image_size=16, **kw)  # type: ignore[arg-type]


@pytest.mark.parametrize("kind", ["rgb8", "bgr8", "mono8", "compressed"])
def test_each_image_kind_decodes_to_rgb(tmp_path: Path, kind: str) -> None:
    d = drive(write_drive_bag(tmp_path / "bag", image_kind=kind))
    assert len(d) == 30 and d.skipped == {}
    expected = picture(7)[0, 0] if kind != "mono8" else np.repeat(picture(7)[0, 0, :1], 3)
    np.testing.assert_array_equal(d.images[7, 5, 5], expected)
    assert d.images.shape == (30, 16, 16, 3) and d.source["camera"] == {"width": 32, "height": 24}


@pytest.mark.parametrize("stamped", [False, True])
def test_frames_carry_the_command_active_at_their_time_and_the_odometry(
    tmp_path: Path, stamped: bool
) -> None:
    d = drive(write_drive_bag(tmp_path / "bag", stamped=stamped, storage="mcap" if stamped else "sqlite3"))
    t = np.arange(len(d)) * 0.1
    np.testing.assert_allclose(d.commands[:, 0], np.where((t >= 1.0) & (t < 1.5), 0.45, 0.2))
    np.testing.assert_allclose(d.commands[:, 1], 0.1)
    np.testing.assert_allclose(d.poses[:3, 0], [0.0, 0.02, 0.04], atol=1e-9)
    np.testing.assert_allclose(d.poses[:, 2], 0.1 * t, atol=1e-9)  # yaw from the quaternion


def test_frames_are_timed_by_their_header_stamps_not_by_when_the_bag_received_them(tmp_path: Path) -> None:
    d = drive(write_drive_bag(tmp_path / "bag", camera_latency=0.12))  # frames arrive 120 ms late
    assert len(d) == 30 and d.source["stamps"] == {
        "image": "header",
        "cmd": "receive (no header)",
        "pose": "header",
    }
    np.testing.assert_array_equal(d.images[:, 0, 0, 0], np.arange(30))  # frame k is picture k
    t = (
        np.arange(30) * 0.1 + 0.003
    )  # its capture time; receive times would pair frame 9 with the fast command
    np.testing.assert_allclose(d.commands[:, 0], np.where((t >= 1.0) & (t < 1.5), 0.45, 0.2))


def test_header_stamps_on_another_clock_fall_back_to_receive_times(tmp_path: Path) -> None:
    d = drive(write_drive_bag(tmp_path / "bag", camera_clock=-1e6))  # a camera stamping from its own boot
    assert len(d) == 30 and d.skipped == {}
    assert d.source["stamps"]["image"] == "receive (header stamps +1000000.0 s off the receive clock)"
    assert "times: image receive (header stamps +1000000.0 s off" in d.report()


def test_a_camera_gap_splits_the_drive_and_is_reported(tmp_path: Path) -> None:
    d = drive(write_drive_bag(tmp_path / "bag", camera_gap=(1.2, 1.8)))
    assert len(np.unique(d.segments)) == 2 and len(d) == 24
    assert d.skipped == {
        "no camera frame within dt/2 of the frame time (camera slower than 1/dt, or a gap)": 6
    }
    assert "skipped 6 frames: no camera frame" in d.report()


def test_a_slow_camera_is_not_duplicated(tmp_path: Path) -> None:
    d = drive(write_drive_bag(tmp_path / "bag", camera_hz=5.0))
    assert len(d) == 15 and sum(d.skipped.values()) == 14
    assert len(set(d.images[:, 0, 0, 0].tolist())) == 15


def test_commands_beyond_the_limits_are_skipped_and_silence_means_zero(tmp_path: Path) -> None:
    d = drive(write_drive_bag(tmp_path / "bag", fast=0.8, cmd_silence=(2.0, 3.0)))
    assert d.skipped == {"command beyond the limits (|v| <= 0.5 m/s, |w| <= 1.0 rad/s)": 5}
    t = np.array([k * 0.1 for k in range(30) if not 1.0 <= k * 0.1 < 1.5 - 1e-9])
    np.testing.assert_allclose(
        d.commands[t > 2.5, 0], 0.0
    )  # the teleop went quiet: the robot's timeout stops it
    np.testing.assert_allclose(d.commands[t < 2.45, 0], 0.2)


def test_a_missing_or_mistyped_topic_names_what_the_bag_has(tmp_path: Path) -> None:
    path = write_drive_bag(tmp_path / "bag")
    with pytest.raises(BagError, match=r"no topic '/camera/rgb'.*/camera/image \(sensor_msgs/msg/Image\)"):
        read_bag([path], "/camera/rgb", "/cmd_vel")
    with pytest.raises(BagError, match="command topic '/odom' carries nav_msgs/msg/Odometry"):
        read_bag([path], "/camera/image", "/odom")


def test_without_rosbags_the_error_names_the_extra(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "rosbags", None)
    with pytest.raises(BagError, match=r"pip install 'vtr-mpc\[ros\]'"):
        read_bag([tmp_path], "/a", "/b")


def test_vtr_collect_bag_writes_a_dataset(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = write_drive_bag(tmp_path / "bag", camera_gap=(1.2, 1.8), odom=False)
    out = tmp_path / "d.npz"
    args = ["collect", "--bag", str(bag), "--image-topic", "/camera/image", "--cmd-topic", "/cmd_vel"]
    assert cli.main([*args, "--out", str(out), "--image-size", "16"]) == 0
    data = load_dataset(out, image_size=16)
    assert len(data) == 24 and data.episodes.tolist() == [0] * 12 + [1] * 12
    assert tuple(data.commands[11]) == (0.0, 0.0) and tuple(data.commands[-1]) == (0.0, 0.0)
    assert data.commands[0, 0] == pytest.approx(0.2)
    assert data.meta["source"] == "vtr collect --bag" and data.meta["poses_known"] is False
    assert "skipped 6 frames" in capsys.readouterr().out


def test_vtr_teach_bag_writes_a_route(tmp_path: Path) -> None:
    bag = write_drive_bag(tmp_path / "bag")
    out = tmp_path / "route.npz"
    args = ["teach", "--bag", str(bag), "--image-topic", "/camera/image", "--cmd-topic", "/cmd_vel"]
    assert cli.main([*args, "--odom-topic", "/odom", "--out", str(out), "--camera-fov", "90"]) == 0
    route = Route.load(out)
    # the 32x24 frames are cropped to 24x24: a 90 degree camera keeps 2 atan(0.75) of its view
    assert route.camera["fov_deg"] == pytest.approx(73.74, abs=0.01) and route.camera["height_m"] is None
    assert len(route) == 16 and route.images.shape[1:] == (128, 128, 3)  # frames 0, 2, ..., 28 and the last
    assert route.commands[0, 0] == pytest.approx(0.2) and tuple(route.commands[-1]) == (0.0, 0.0)
    assert route.poses[1, 0] == pytest.approx(0.04) and route.dt == 0.1


def test_vtr_teach_bag_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["teach", "--bag", str(tmp_path / "nope"), "--out", str(tmp_path / "r.npz")]) == 2
    assert "--bag needs --image-topic and --cmd-topic" in capsys.readouterr().err
    args = ["teach", "--bag", str(tmp_path / "nope"), "--image-topic", "/i", "--cmd-topic", "/c"]
    assert cli.main([*args, "--out", str(tmp_path / "r.npz")]) == 2
    assert "no bag at" in capsys.readouterr().err


def _teach(bag: Path, out: Path, *more: str) -> int:
    args = ["teach", "--bag", str(bag), "--image-topic", "/camera/image", "--cmd-topic", "/cmd_vel"]
    return cli.main([*args, "--out", str(out), *more])


def test_vtr_teach_bag_reads_the_field_of_view_from_camera_info(tmp_path: Path) -> None:
    bag = write_drive_bag(tmp_path / "bag", odom=False, camera_info_fx=16.0)  # 32 px wide: 90 degrees
    assert _teach(bag, tmp_path / "route.npz") == 0
    camera = Route.load(tmp_path / "route.npz").camera
    assert camera["fov_deg"] == pytest.approx(73.74, abs=0.01)  # cropped to 24x24, as with --camera-fov 90
    assert camera["fov_from"] == "sensor_msgs/CameraInfo on /camera/camera_info"
    assert camera["unknown"] == ["height_m"]  # CameraInfo says nothing of the mounting height


@pytest.mark.parametrize("fx", [None, 0.0])  # no CameraInfo; an uncalibrated one
def test_a_bag_without_camera_facts_stores_an_unknown_field_of_view_that_repeat_refuses(
    tmp_path: Path, fx: float | None, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_drive_bag(tmp_path / "bag", odom=False, camera_info_fx=fx)
    route = tmp_path / "route.npz"
    assert _teach(bag, route) == 0
    assert "the route records its field of view as unknown" in capsys.readouterr().err
    assert Route.load(route).camera["unknown"] == ["fov_deg", "height_m"]
    model = str(Path(__file__).resolve().parents[2] / "models" / "velocitynet.onnx")
    code = cli.main(["repeat", "--sim", "tcp://127.0.0.1:9", "--model", model, "--route", str(route)])
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "field of view is unknown" in line and "re-teach it with --camera-fov DEG" in line
