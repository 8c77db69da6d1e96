"""The request fast path must be invisible: same bytes as the general path (json.dumps + decode_request),
same refusals with the same words, for valid and invalid values alike."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vtr.runtime import protocol
from vtr.runtime.protocol import Limits, ProtocolError

FAST = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])

numbers = (
    st.floats()  # NaN and inf included: both paths must refuse them alike
    | st.integers(min_value=-(10**17), max_value=10**17)
    | st.sampled_from([0.0, -0.0, 1e15, -1e15, 1e15 + 1, 5e-324, True, None, "0.1", np.float32(0.5)])
)
sessions = st.none() | st.text(max_size=70) | st.sampled_from(["bench", "", "x" * 64, "x" * 65, 7])


def _outcome(fn, *args):
    try:
        return ("ok", fn(*args))
    except ProtocolError as exc:
        return ("refused", str(exc))


def _both(cmd, seq, stamp, limits, fields):
    fast = _outcome(lambda: protocol.encode_request(cmd, seq, stamp, limits, **fields))
    general = _outcome(lambda: protocol.encode_request_checked(cmd, seq, stamp, limits, dict(fields)))
    return fast, general


@FAST
@given(
    cmd=st.sampled_from(protocol.COMMANDS),
    seq=st.integers(min_value=-3, max_value=2**53 + 3) | st.sampled_from([True, 2.0, np.int64(4)]),
    stamp=numbers,
    session=sessions,
    v=numbers,
    w=numbers,
    duration=numbers,
    limits=st.sampled_from([None, Limits()]),
    extra=st.sampled_from([{}, {"seed": 3}, {"pose": (1.0, 2.0, 0.5)}, {"colour": "red"}]),
)
def test_fast_path_equals_general_path(cmd, seq, stamp, session, v, w, duration, limits, extra):
    fields = {"session": session, **extra}
    if cmd == "step":
        fields.update(v=v, w=w, duration=duration)
    fast, general = _both(cmd, seq, stamp, limits, fields)
    assert fast == general


@FAST
@given(
    v=st.floats(min_value=-0.5, max_value=0.5),
    w=st.floats(min_value=-1.0, max_value=1.0),
    duration=st.floats(min_value=1e-3, max_value=10.0),
    stamp=st.floats(min_value=0.0, max_value=2e9),
)
def test_valid_step_requests_are_identical_bytes(v, w, duration, stamp):
    fields = {"session": "s-1", "v": v, "w": w, "duration": duration}
    fast, general = _both("step", 12, stamp, Limits(), fields)
    assert fast[0] == "ok" and fast == general


@pytest.mark.parametrize(
    ("cmd", "fields"),
    [("step", {"v": 0.9, "w": 0.0, "duration": 0.1}), ("step", {"v": 0.1, "w": 0.0, "duration": 0.0})],
)
def test_fast_path_refusals_keep_their_wording(cmd, fields):
    with pytest.raises(ProtocolError, match="out of range"):
        protocol.encode_request(cmd, 1, 1.0, Limits(), **fields)


def test_common_requests_take_the_fast_path():
    templates = protocol._TEMPLATES
    args = ("step", 3, 1.5, Limits(), {"session": "a", "v": 0.1, "w": 0.2, "duration": 0.25})
    assert templates.header(*args) is not None
    assert templates.header("stop", 4, 1.5, None, {}) is not None
    assert templates.header("reset", 1, None, None, {"seed": 1}) is None  # general path
