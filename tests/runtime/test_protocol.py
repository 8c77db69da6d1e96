"""The wire contract, without sockets: round trips and every malformed input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vtr.runtime import protocol
from vtr.runtime.protocol import BadFrameError, Limits, ProtocolError


def header(**overrides):
    h = {"proto": "vtr-sim", "version": 1, "cmd": "observe", "seq": 1, "stamp": 0.0}
    h.update(overrides)
    return [json.dumps(h).encode()]


def image(h=4, w=5):
    return np.arange(h * w * 3, dtype=np.uint8).reshape(h, w, 3)


# ------------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("cmd", ["hello", "observe", "stop"])
def test_simple_requests_round_trip(cmd):
    req = protocol.decode_request(protocol.encode_request(cmd, 7, stamp=1.5))
    assert (req.cmd, req.seq, req.stamp, req.fields) == (cmd, 7, 1.5, {})


def test_step_request_round_trip():
    req = protocol.decode_request(protocol.encode_request("step", 3, v=0.25, w=-0.5, duration=0.1))
    assert req.cmd == "step" and req.fields == {"v": 0.25, "w": -0.5, "duration": 0.1}


def test_reset_request_round_trip_with_and_without_pose():
    req = protocol.decode_request(protocol.encode_request("reset", 1, pose=(1.0, -2.0, 0.5), seed=4))
    assert req.fields == {"pose": (1.0, -2.0, 0.5), "seed": 4}
    assert protocol.decode_request(protocol.encode_request("reset", 2)).fields == {}


def test_image_reply_round_trip():
    img = image()
    frames = protocol.encode_image_reply("step", 9, "abc", 2.5, img, pose=(1.0, 2.0, 3.0), collided=True)
    assert len(frames) == 2
    reply = protocol.decode_reply(frames, expect_cmd="step", expect_seq=9, expect_shape=(4, 5))
    assert reply.ok and reply.stamp == 2.5 and reply.session == "abc" and reply.collided
    assert reply.pose == (1.0, 2.0, 3.0)
    np.testing.assert_array_equal(reply.image, img)
    assert reply.header["encoding"] == "rgb8" and (reply.header["height"], reply.header["width"]) == (4, 5)


def test_ok_and_error_replies_round_trip():
    reply = protocol.decode_reply(protocol.encode_ok("hello", 1, "s", 0.0, limits={"v_max": 0.5}))
    assert reply.ok and reply.header["limits"] == {"v_max": 0.5}
    err = protocol.decode_reply(protocol.encode_error("bad thing", "step", 4, "s"))
    assert not err.ok and err.error == "bad thing" and err.cmd == "step" and err.seq == 4


def test_pose_dict_accepts_objects_and_tuples():
    class P:
        x, y, yaw = 1, 2, 3

    assert protocol.pose_dict(P()) == protocol.pose_dict((1, 2, 3)) == {"x": 1.0, "y": 2.0, "yaw": 3.0}
    assert protocol.pose_dict(None) is None


# ------------------------------------------------------------------------------- bad requests


BAD_REQUESTS = {
    "malformed JSON": ([b"{not json"], "malformed JSON"),
    "not utf-8": ([b"\xff\xfe"], "malformed JSON"),
    "not an object": ([b"[1, 2]"], "JSON object"),
    "empty message": ([], "empty message"),
    "wrong proto": (header(proto="ros"), "wrong protocol"),
    "wrong version": (header(version=2), "unsupported protocol version 2"),
    "bool version": (header(version=True), "unsupported protocol version"),
    "unknown command": (header(cmd="fly"), "unknown command 'fly'"),
    "missing seq": (
        [json.dumps({"proto": "vtr-sim", "version": 1, "cmd": "hello", "stamp": 0}).encode()],
        "'seq'",
    ),
    "float seq": (header(seq=1.5), "'seq' must be an integer"),
    "missing v": (header(cmd="step", w=0.0, duration=0.1), "missing field 'v'"),
    "string v": (header(cmd="step", v="fast", w=0.0, duration=0.1), "'v' must be a number"),
    "NaN v": (
        [b'{"proto":"vtr-sim","version":1,"cmd":"step","seq":1,"stamp":0,"v":NaN,"w":0,"duration":0.1}'],
        "non-finite",
    ),
    "infinite w": (
        [b'{"proto":"vtr-sim","version":1,"cmd":"step","seq":1,"stamp":0,"v":0,"w":Infinity,"duration":0.1}'],
        "non-finite",
    ),
    "huge number": (
        [b'{"proto":"vtr-sim","version":1,"cmd":"step","seq":1,"stamp":0,"v":1e999,"w":0,"duration":0.1}'],
        "out of range",
    ),
    "v over limit": (header(cmd="step", v=0.6, w=0.0, duration=0.1), "v_max=0.5"),
    "w over limit": (header(cmd="step", v=0.0, w=-1.5, duration=0.1), "w_max=1.0"),
    "zero duration": (header(cmd="step", v=0.0, w=0.0, duration=0.0), "duration=0.0"),
    "long duration": (header(cmd="step", v=0.0, w=0.0, duration=11.0), "duration=11.0"),
    "bad pose": (header(cmd="reset", pose={"x": 1.0, "y": 2.0}), "missing field pose.'yaw'"),
    "pose not object": (header(cmd="reset", pose=[1, 2, 3]), "'pose' must be an object"),
    "negative seed": (header(cmd="reset", seed=-1), "'seed' must be >= 0"),
    "extra frame": (header() + [b"payload"], "one header frame"),
    "oversized header": ([b" " * (protocol.MAX_HEADER_BYTES + 1)], "header frame of"),
    "oversized message": (header() + [b"x" * 2000], "exceeds the limit of 1024 bytes"),
}


@pytest.mark.parametrize("name", list(BAD_REQUESTS))
def test_bad_requests_raise_protocol_error_naming_the_problem(name):
    frames, fragment = BAD_REQUESTS[name]
    with pytest.raises(ProtocolError) as info:
        protocol.decode_request(frames, max_message_bytes=1024 if name == "oversized message" else 10**6)
    assert fragment in str(info.value)


def test_limits_are_configurable():
    frames = header(cmd="step", v=0.8, w=0.0, duration=0.1)
    with pytest.raises(ProtocolError, match="v_max=0.5"):
        protocol.decode_request(frames)
    assert protocol.decode_request(frames, Limits(v_max=1.0)).fields["v"] == 0.8
    with pytest.raises(ValueError, match="v_max"):
        Limits(v_max=-1)


def test_encode_request_refuses_what_the_server_would_refuse():
    with pytest.raises(ProtocolError, match="v_max"):
        protocol.encode_request("step", 1, limits=Limits(), v=0.9, w=0.0, duration=0.1)
    # without limits (a client that has not read hello) only the shape is checked; the server checks ranges
    assert protocol.decode_request(protocol.encode_request("step", 1, v=0.9, w=0.0, duration=0.1), None)
    with pytest.raises(ProtocolError, match="unknown command"):
        protocol.encode_request("dance", 1)
    with pytest.raises(ProtocolError, match="cannot encode"):
        protocol.encode_request("step", 1, v=float("nan"), w=0.0, duration=0.1)


def test_peek_cmd_seq_is_best_effort():
    assert protocol.peek_cmd_seq(header(cmd="step", seq=5)) == ("step", 5)
    assert protocol.peek_cmd_seq([b"\x00garbage"]) == (None, None)


# ------------------------------------------------------------------------------- bad replies


def good_reply(**overrides):
    frames = protocol.encode_image_reply("observe", 1, "s", 1.0, image())
    h = json.loads(frames[0])
    h.update(overrides)
    return [json.dumps(h).encode(), frames[1]]


def test_bad_replies_raise_bad_frame_error():
    cases = {
        "unsupported image encoding": good_reply(encoding="bgr8"),
        "unsupported protocol version": good_reply(version=3),
        "truncated pixel frame": [good_reply()[0], good_reply()[1][:-1]],
        "oversized pixel frame": [good_reply()[0], good_reply()[1] + b"x"],
        "must have 2 frames": good_reply()[:1],
        "image is 4x5, expected 8x8": good_reply(),
        "out of range": good_reply(height=0),
        "'ok' must be true or false": good_reply(ok="yes"),
        "expected 'observe'": good_reply(cmd="step"),
        "stale or out of order": good_reply(seq=0),
        "'stamp' must be a number": good_reply(stamp=None),
        "pose.'x'": good_reply(pose={"x": "a", "y": 0, "yaw": 0}),
    }
    for fragment, frames in cases.items():
        with pytest.raises(BadFrameError) as info:
            protocol.decode_reply(
                frames,
                expect_cmd="observe",
                expect_seq=1,
                expect_shape=(8, 8) if fragment.startswith("image is") else None,
            )
        assert fragment in str(info.value), (fragment, str(info.value))


def test_decoded_image_is_exactly_the_payload_layout():
    img = np.zeros((2, 3, 3), dtype=np.uint8)
    img[1, 2] = (10, 20, 30)  # row 1, column 2: RGB
    reply = protocol.decode_reply(protocol.encode_image_reply("observe", 1, "s", 0.0, img))
    assert tuple(reply.image[1, 2]) == (10, 20, 30) and reply.image.sum() == 60


def test_encode_image_reply_refuses_wrong_dtype():
    with pytest.raises(ProtocolError, match="uint8"):
        protocol.encode_image_reply("observe", 1, "s", 0.0, np.zeros((2, 2, 3), dtype=np.float32))


def test_jsonable_flattens_simulator_info():
    from dataclasses import dataclass

    @dataclass
    class Cam:
        width: int = 4
        fov: float = float("nan")

    out = protocol.jsonable({"camera": Cam(), "arr": np.arange(2), "t": 1.0})
    assert out == {"camera": {"width": 4, "fov": None}, "arr": [0, 1], "t": 1.0}
