"""MCAP out: a run written by McapRunWriter reads back with rosbags and with the mcap package's reader, with the
ROS 2 message types Foxglove and `ros2 bag play` expect."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from runtime_fakes import FakeSim, build_velocitynet_onnx, corridor_route

from vtr import cli
from vtr.runtime.mcap_log import TOPICS, McapRunWriter
from vtr.runtime.mcap_read import read_run
from vtr.sim2d.server import ServerThread


def steps(n: int = 6) -> list[dict]:
    out = []
    for k in range(n):
        out.append(
            {
                "stamp": 3.0 + 0.1 * k,
                "image": np.full((8, 10, 3), (k, 50, 200), np.uint8),
                "subgoal_image": np.full((8, 10, 3), 7, np.uint8),
                "v": 0.05 * k,
                "w": -0.3,
                "pose": None if k == 2 else (0.1 * k, -0.5, 0.2 * k),
                "error": 20.0 - k,
                "subgoal": k // 2,
                "decision": "steer",
                "step": k,
            }
        )
    return out


def write(path: Path, n: int = 6) -> Path:
    with McapRunWriter(path) as writer:
        for step in steps(n):
            writer.record(step)
        writer.record_summary({"completed": True, "reason": "finished"})
    return path


@pytest.mark.parametrize("name", ["run.mcap", "run_bag"])
def test_a_run_reads_back_with_rosbags(tmp_path: Path, name: str) -> None:
    path = write(tmp_path / name)
    assert [p.name for p in tmp_path.iterdir()] == [name]  # the temporary folder is gone
    if name == "run_bag":
        assert sorted(p.name for p in path.iterdir()) == ["metadata.yaml", "run_bag.mcap"]
    with AnyReader([path]) as reader:
        assert {c.topic: c.msgtype for c in reader.connections} == TOPICS
        images = [
            reader.deserialize(raw, c.msgtype)
            for c, _, raw in reader.messages()
            if c.topic == "/vtr/camera/image"
        ]
    assert (
        len(images) == 6 and images[3].encoding == "rgb8" and (images[3].height, images[3].width) == (8, 10)
    )
    np.testing.assert_array_equal(np.asarray(images[3].data).reshape(8, 10, 3)[0, 0], (3, 50, 200))
    run = read_run(path)
    np.testing.assert_allclose(run.times, 0.1 * np.arange(6), atol=1e-6)
    np.testing.assert_allclose(run.commands[:, 0], 0.05 * np.arange(6))
    np.testing.assert_allclose(run.commands[:, 1], -0.3)
    assert np.isnan(run.poses[2]).all()
    np.testing.assert_allclose(
        run.poses[[0, 1, 3, 4, 5]], [(0.1 * k, -0.5, 0.2 * k) for k in (0, 1, 3, 4, 5)], atol=1e-9
    )
    np.testing.assert_allclose(run.errors, 20.0 - np.arange(6))
    assert run.steps[4] == {
        "step": 4,
        "subgoal": 2,
        "error": 16.0,
        "decision": "steer",
        "v": 0.2,
        "w": -0.3,
        "stamp": 3.4,
    }
    assert run.summary == {"completed": True, "reason": "finished"} and run.image_count == 6


def test_the_mcap_reader_sees_ros2_schemas_and_cdr(tmp_path: Path) -> None:
    path = write(tmp_path / "run.mcap")
    store = get_typestore(Stores.ROS2_HUMBLE)
    seen: dict[str, tuple[str, str, str]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            seen[channel.topic] = (schema.name, schema.encoding, channel.message_encoding)
            msg = store.deserialize_cdr(message.data, schema.name)  # the bytes are CDR of the announced type
            if channel.topic == "/vtr/cmd_vel":
                assert msg.header.frame_id == "base_link" and msg.twist.angular.z == pytest.approx(-0.3)
                assert message.log_time == msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            if channel.topic == "/vtr/pose":
                assert msg.header.frame_id == "map"
                assert 2 * math.atan2(msg.pose.orientation.z, msg.pose.orientation.w) == pytest.approx(
                    0.2 * (msg.pose.position.x / 0.1), abs=1e-9
                )
            if channel.topic == "/vtr/step" and "summary" not in msg.data:
                assert json.loads(msg.data)["decision"] == "steer"
        assert reader.get_summary().statistics.message_count == 6 * 6 - 1 + 1  # no pose once, a summary
    assert seen == {topic: (msgtype, "ros2msg", "cdr") for topic, msgtype in TOPICS.items()}


def test_an_unfinished_run_is_never_at_the_final_path(tmp_path: Path) -> None:
    writer = McapRunWriter(tmp_path / "run.mcap")
    writer.record(steps(1)[0])
    assert not (tmp_path / "run.mcap").exists()
    writer.close()
    assert read_run(tmp_path / "run.mcap").commands.shape == (1, 2)


def test_without_rosbags_the_error_names_the_extra(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "rosbags", None)
    with pytest.raises(ModuleNotFoundError, match=r"pip install 'vtr-mpc\[ros\]'"):
        McapRunWriter(tmp_path / "run.mcap")


def test_vtr_repeat_mcap_writes_the_whole_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    model = build_velocitynet_onnx(str(tmp_path / "tiny.onnx"))
    route_path = tmp_path / "route.npz"
    route = corridor_route()
    route.save(route_path)
    out = tmp_path / "run.mcap"
    with ServerThread(FakeSim()) as server:
        argv = ["repeat", "--sim", server.endpoint, "--model", model, "--route", str(route_path), "--json"]
        argv += ["--profile", "paper"]  # the fake policy steers on brightness, which light matching evens out
        assert cli.main([*argv, "--mcap", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out)
    run = read_run(out)
    assert len(run.commands) == summary["steps"] + 1  # every command, and the record that ended the run
    assert run.summary is not None and run.summary["status"] == "finished"
    assert run.steps[-1]["decision"] == "finished" and tuple(run.commands[-1]) == (0.0, 0.0)
    assert run.steps[0]["decision"] == "command" and run.commands[:, 0].max() > 0
    assert np.isfinite(run.poses).all() and run.poses[-1, 0] > run.poses[0, 0]  # it drove along the corridor
    np.testing.assert_allclose(run.times[1], 0.1, atol=1e-6)  # the robot's clock
    with AnyReader([out]) as reader:
        goals = [
            reader.deserialize(r, c.msgtype)
            for c, _, r in reader.messages()
            if c.topic == "/vtr/subgoal/image"
        ]
    first = run.steps[0]["subgoal"]
    np.testing.assert_array_equal(
        np.asarray(goals[0].data).reshape(route.images.shape[1:]), route.images[first]
    )
