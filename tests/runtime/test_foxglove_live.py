"""`vtr repeat --foxglove`: the live view serves the run's channels on 127.0.0.1 (checked through an MCAP sink on
the same Foxglove context, which receives exactly what a connected Foxglove would)."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import foxglove  # the optional extra [foxglove] (in [dev]), never part of the robot install
import numpy as np
import pytest
from mcap.reader import make_reader

from vtr.runtime.foxglove_live import FoxgloveLive


def test_live_view_serves_images_pose_and_step_json_on_localhost(tmp_path: Path) -> None:
    context = foxglove.Context()
    live = FoxgloveLive(port=0, context=context)
    sink = foxglove.open_mcap(tmp_path / "seen.mcap", context=context)
    try:
        with socket.create_connection(("127.0.0.1", live.port), timeout=2):
            pass
        for k in range(3):
            live.record(
                {
                    "stamp": 1.5 + 0.1 * k,
                    "image": np.full((6, 8, 3), k, np.uint8),
                    "subgoal_image": np.zeros((6, 8, 3), np.uint8),
                    "pose": (0.1 * k, 0.0, 0.5) if k != 1 else None,
                    "v": 0.2,
                    "w": 0.0,
                    "error": 9.0,
                    "subgoal": k,
                    "decision": "command",
                }
            )
    finally:
        sink.close()
        live.close()
    topics: dict[str, list[tuple[str, bytes]]] = {}
    with open(tmp_path / "seen.mcap", "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            topics.setdefault(channel.topic, []).append((schema.name, message.data))
    assert {t: len(m) for t, m in topics.items()} == {
        "/vtr/camera/image": 3,
        "/vtr/subgoal/image": 3,
        "/vtr/pose": 2,
        "/vtr/step": 3,
    }
    assert topics["/vtr/camera/image"][0][0] == "foxglove.RawImage"
    assert topics["/vtr/pose"][0][0] == "foxglove.PoseInFrame"
    assert json.loads(topics["/vtr/step"][2][1]) == {
        "stamp": pytest.approx(1.7),
        "v": 0.2,
        "w": 0.0,
        "error": 9.0,
        "subgoal": 2,
        "decision": "command",
    }
