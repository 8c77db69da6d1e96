"""The executed twist in image replies (docs/PROTOCOL.md, "Executed twist"): optional, announced in hello, read
only when announced; replies without it (every bridge written before it) still decode."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vtr.runtime import protocol
from vtr.runtime.hello import read_hello
from vtr.runtime.protocol import BadFrameError

IMAGE = np.zeros((4, 6, 3), np.uint8)


def _reply(**header_changes: object) -> list[bytes]:
    frames = protocol.encode_image_reply("step", 3, "s1", 1.5, IMAGE, (1.0, 2.0, 0.5), twist=(0.2, -0.3))
    header = json.loads(frames[0])
    header.update(header_changes)
    return [json.dumps(header).encode(), frames[1]]


def test_the_twist_round_trips_when_announced_and_is_ignored_otherwise():
    frames = protocol.encode_image_reply("step", 3, "s1", 1.5, IMAGE, None, twist=(0.2, -0.3))
    assert json.loads(frames[0])["twist"] == {"v": 0.2, "w": -0.3}
    assert protocol.decode_reply(frames, expect_twist=True).twist == (0.2, -0.3)
    assert protocol.decode_reply(frames).twist is None  # hello did not announce it: not read


def test_a_reply_without_a_twist_still_decodes():
    old = protocol.encode_image_reply("observe", 4, "s1", 1.5, IMAGE, None)
    assert "twist" not in json.loads(old[0])
    assert protocol.decode_reply(old, expect_twist=True).twist is None
    assert protocol.decode_reply(_reply(twist=None), expect_twist=True).twist is None  # null alike


@pytest.mark.parametrize(
    ("twist", "words"),
    [
        ([0.2, 0.1], "must be an object with 'v' and 'w'"),
        ({"v": 0.2}, "missing field twist.'w'"),
        ({"v": "fast", "w": 0.0}, "twist.'v' must be a number"),
        ({"v": True, "w": 0.0}, "twist.'v' must be a number"),
    ],
)
def test_a_bad_twist_is_a_bad_frame_naming_it(twist, words):
    with pytest.raises(BadFrameError, match="twist") as err:
        protocol.decode_reply(_reply(twist=twist), expect_twist=True)
    assert words in str(err.value)
    assert protocol.decode_reply(_reply(twist=twist)).twist is None  # unannounced: ignored, as the doc says


def test_hello_announces_where_the_twist_comes_from():
    base = {
        "protocol_version": 1,
        "camera": {"width": 6, "height": 4},
        "limits": {"v_max": 0.5, "w_max": 1.0, "max_duration": 10.0},
    }

    def hello(**extra: object):
        return read_hello(protocol.decode_reply(protocol.encode_ok("hello", 1, "s", 0.0, **base, **extra)))

    assert hello()[0].twist is None
    assert hello(twist={"source": "measured"})[0].twist == "measured"
    assert hello(twist={"source": "commanded"})[0].twist == "commanded"
    wrong, problems = hello(twist={"source": "guessed"})
    assert wrong.twist is None and "'source' one of ('measured', 'commanded')" in problems["twist"]
