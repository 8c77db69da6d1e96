"""Property tests of the codec: whatever the bytes, decoding returns or raises ProtocolError/BadFrameError only.

Budgets are small (CI has 2 cores); `benchmarks/link_faults.py` runs the 10,000-message versions.
"""

from __future__ import annotations

import json

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vtr.runtime import protocol
from vtr.runtime.protocol import BadFrameError, Limits, ProtocolError

FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(min_value=-(10**30), max_value=10**30)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=8),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=6), children, max_size=4)
    ),
    max_leaves=20,
)
keys = st.sampled_from(
    [
        "proto",
        "version",
        "cmd",
        "seq",
        "stamp",
        "v",
        "w",
        "duration",
        "pose",
        "seed",
        "session",
        "ok",
        "height",
        "width",
        "encoding",
        "collided",
        "error",
    ]
)


@st.composite
def near_valid_headers(draw) -> dict:
    """A valid header with a few fields replaced by arbitrary JSON: where the interesting bugs live."""
    header = {
        "proto": "vtr-sim",
        "version": 1,
        "cmd": draw(st.sampled_from(protocol.COMMANDS)),
        "seq": 3,
        "stamp": 1.0,
    }
    header.update(v=0.1, w=0.0, duration=0.1, ok=True, session="s", encoding="rgb8", height=2, width=2)
    for key in draw(st.lists(keys, max_size=4)):
        header[key] = draw(json_values)
    return header


def frames_of(header: dict, extra: list[bytes]) -> list[bytes]:
    return [json.dumps(header).encode(), *extra]


@FAST
@given(st.lists(st.binary(max_size=64), min_size=0, max_size=3))
def test_random_bytes_raise_only_protocol_errors(frames):
    for decode, err in ((protocol.decode_request, ProtocolError), (protocol.decode_reply, BadFrameError)):
        try:
            decode(frames)
        except err:
            pass


@FAST
@given(near_valid_headers(), st.lists(st.binary(max_size=16), max_size=2))
def test_near_valid_headers_decode_or_raise_only_protocol_errors(header, extra):
    frames = frames_of(header, extra)
    try:
        req = protocol.decode_request(frames)
        assert req.cmd in protocol.COMMANDS and type(req.seq) is int
    except ProtocolError:
        pass
    try:
        reply = protocol.decode_reply(frames)
        assert reply.ok is False or (type(reply.seq) is int and reply.stamp is not None)
    except BadFrameError:
        pass


@FAST
@given(
    st.floats(min_value=-0.5, max_value=0.5),
    st.floats(min_value=-1.0, max_value=1.0),
    st.floats(min_value=1e-3, max_value=10.0),
    st.integers(min_value=0, max_value=protocol.MAX_INT),
)
def test_valid_steps_round_trip_exactly(v, w, duration, seq):
    req = protocol.decode_request(
        protocol.encode_request("step", seq, 2.5, Limits(), v=v, w=w, duration=duration)
    )
    assert (req.cmd, req.seq, req.stamp) == ("step", seq, 2.5)
    assert req.fields == {"v": v, "w": w, "duration": duration}


@FAST
@given(st.integers(1, 6), st.integers(1, 6), st.binary(min_size=0, max_size=0))
def test_image_replies_round_trip(height, width, _):
    image = np.random.default_rng(height * 7 + width).integers(0, 256, (height, width, 3), dtype=np.uint8)
    reply = protocol.decode_reply(protocol.encode_image_reply("observe", 9, "s", 1.5, image, (1.0, 2.0, 0.5)))
    np.testing.assert_array_equal(reply.image, image)
    assert reply.pose == (1.0, 2.0, 0.5) and reply.seq == 9 and reply.session == "s"


def test_hostile_numbers_and_nesting_are_refused_by_name():
    base = b'{"proto":"vtr-sim","version":1,"cmd":"step","seq":1,"v":%s,"w":0,"duration":0.1}'
    for value, fragment in (
        (b"9" * 400, b"out of range"),
        (b"-" + b"9" * 5000, b"out of range"),
        (b"1e400", b"out of range"),
        (b"1e16", b"out of range"),
        (b"[" * 1000 + b"]" * 1000, b"nested deeper"),
    ):
        try:
            protocol.decode_request([base % value])
        except ProtocolError as exc:
            assert fragment.decode() in str(exc)
        else:
            raise AssertionError(f"accepted {value[:20]!r}")
