"""The optional range scan on the wire: announced in hello, carried by image replies, checked at the decoder."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from vtr.runtime import protocol
from vtr.runtime.hello import parse_hello
from vtr.runtime.protocol import BadFrameError
from vtr.runtime.scan import MAX_BEAMS, Scan, ScanSpec, scan_from_wire, spec_from_dict

SPEC = ScanSpec(beams=5, angle_min=-1.0, angle_increment=0.5, range_max=4.0, x_m=0.1)
IMAGE = np.zeros((2, 3, 3), dtype=np.uint8)


def scan(ranges=(0.5, np.inf, 1.2344, 4.0, 0.0)) -> Scan:
    return Scan(
        SPEC.angle_min, SPEC.angle_increment, SPEC.range_max, np.asarray(ranges, np.float32), SPEC.x_m
    )


def reply_frames(scan_field) -> list[bytes]:
    frames = protocol.encode_image_reply("step", 3, "s", 1.0, IMAGE)
    header = json.loads(frames[0])
    header["scan"] = scan_field
    return [json.dumps(header).encode(), frames[1]]


def wire(**changes):
    d = {"angle_min": -1.0, "angle_increment": 0.5, "range_max": 4.0, "ranges": [0.5, None, 1.2, 4.0, 0]}
    d.update(changes)
    return d


def test_a_scan_round_trips_in_millimetres_with_inf_for_nothing_seen():
    frames = protocol.encode_image_reply("step", 3, "s", 1.0, IMAGE, scan=scan())
    assert len(frames) == 2  # the ranges ride in the header: an image reply stays two frames
    got = protocol.decode_reply(frames, expect_scan=SPEC).scan
    assert got is not None and got.x_m == 0.1 and got.beams == 5
    np.testing.assert_array_equal(got.ranges, np.float32([0.5, np.inf, 1.234, 4.0, 0.0]))
    assert not got.ranges.flags.writeable
    assert json.loads(frames[0])["scan"]["ranges"][1] is None


def test_without_an_announcement_the_scan_is_not_read():
    """A client that knows of no scanner (or an older one) decodes the same reply, scan ignored."""
    reply = protocol.decode_reply(reply_frames({"not": "checked"}))
    assert reply.ok and reply.scan is None and reply.image is not None


@pytest.mark.parametrize("field", [None, "absent"])
def test_a_reply_without_a_reading_has_no_scan(field):
    frames = reply_frames(field) if field is None else protocol.encode_image_reply("step", 3, "s", 1.0, IMAGE)
    assert protocol.decode_reply(frames, expect_scan=SPEC).scan is None


def test_values_beyond_range_max_mean_nothing_seen():
    got = protocol.decode_reply(reply_frames(wire(ranges=[4.5, 1e9, 3.999, 2, None])), expect_scan=SPEC).scan
    np.testing.assert_array_equal(got.ranges, np.float32([np.inf, np.inf, 3.999, 2.0, np.inf]))


@pytest.mark.parametrize(
    ("field", "fragment"),
    [
        ([1, 2], "'scan' must be an object or null"),
        (wire(ranges=[0.5, 1.0]), "'scan.ranges' has 2 values, but hello announced 5 beams"),
        (wire(ranges=[0.5, -0.1, 1, 1, 1]), r"'scan.ranges\[1\]' must be >= 0"),
        (wire(ranges=[0.5, True, 1, 1, 1]), r"'scan.ranges\[1\]' must be a number or null"),
        (wire(ranges=[0.5, 1, "2", 1, 1]), r"'scan.ranges\[2\]' must be a number or null"),
        (wire(ranges=[0.5, 1, 1, [1], 1]), r"'scan.ranges\[3\]' must be a number or null"),
        (wire(ranges="0.5 1 1 1 1"), "'scan.ranges' must be a list"),
        (wire(ranges=None), "'scan.ranges' must be a list"),
        (wire(angle_min=-1.1), "'scan.angle_min' is -1.1, but hello announced -1.0"),
        (wire(angle_increment=0.25), "'scan.angle_increment'"),
        (wire(range_max=30.0), "'scan.range_max'"),
        (wire(range_max="4"), "scan.'range_max' must be a number"),
        ({"ranges": [1, 1, 1, 1, 1]}, "missing field scan.'angle_min'"),
    ],
)
def test_a_bad_scan_is_a_bad_frame_naming_the_field(field, fragment):
    with pytest.raises(BadFrameError, match=fragment):
        protocol.decode_reply(reply_frames(field), expect_scan=SPEC)


def test_float32_rounding_of_the_angles_is_tolerated():
    f32 = {k: float(np.float32(v)) for k, v in (("angle_min", -1.1), ("angle_increment", 0.0043633))}
    spec = ScanSpec(5, -1.1, 0.0043633, 4.0)
    assert scan_from_wire(wire(**f32), spec).angle_increment == 0.0043633


def test_the_largest_scan_fits_the_header_limit_even_at_full_float_precision():
    ranges = [1.2345678901234567] * MAX_BEAMS
    header = json.dumps(wire(ranges=ranges), separators=(",", ":")).encode()
    assert len(header) < protocol.MAX_HEADER_BYTES // 2


HELLO = {
    "protocol_version": 1,
    "camera": {"width": 3, "height": 2},
    "limits": {"v_max": 0.5, "w_max": 1.0, "max_duration": 10.0},
    "dt": 0.02,
    "mode": "lockstep",
}


def test_hello_announces_the_scanner_or_nothing():
    reply = protocol.decode_reply(protocol.encode_ok("hello", 1, "s", 0.0, **HELLO, scan=SPEC.to_dict()))
    assert parse_hello(reply).scan == SPEC
    assert parse_hello(protocol.decode_reply(protocol.encode_ok("hello", 1, "s", 0.0, **HELLO))).scan is None
    no_mount = {k: v for k, v in SPEC.to_dict().items() if k != "x_m"}
    assert spec_from_dict(no_mount).x_m == 0.0


@pytest.mark.parametrize(
    ("changes", "fragment"),
    [
        ({"beams": 0}, "beams must be in 1..1081"),
        ({"beams": MAX_BEAMS + 1}, "beams must be in 1..1081"),
        ({"beams": 5.0}, "'beams' must be an integer"),
        ({"angle_increment": 0.0}, "angle_increment must be non-zero"),
        ({"beams": 361, "angle_increment": math.radians(1.01)}, "span at most 2 pi"),
        ({"angle_min": 7.0}, "angle_min must be in"),
        ({"range_max": 0.0}, r"range_max must be in \(0, 100\]"),
        ({"range_max": 1000.0}, "range_max must be in"),
        ({"x_m": 6.0}, "x_m must be within"),
        ({"angle_min": None}, "missing field scan.'angle_min'"),
    ],
)
def test_a_bad_announcement_is_refused_naming_the_field(changes, fragment):
    spec = {**SPEC.to_dict(), **changes}
    if changes.get("angle_min", 0) is None:
        del spec["angle_min"]
    reply = protocol.decode_reply(protocol.encode_ok("hello", 1, "s", 0.0, **HELLO, scan=spec))
    with pytest.raises(BadFrameError, match=fragment):
        parse_hello(reply)


def test_a_clockwise_scanner_may_announce_a_negative_increment():
    assert (
        spec_from_dict({**SPEC.to_dict(), "angle_min": 1.0, "angle_increment": -0.5}).angle_increment == -0.5
    )


@pytest.mark.parametrize(
    "ranges",
    [[-0.1, 1.0], [np.nan, 1.0], [5.0, 1.0], [[1.0, 2.0]], []],
    ids=["neg", "nan", "far", "2d", "empty"],
)
def test_a_scan_refuses_values_it_cannot_mean(ranges):
    with pytest.raises(ValueError, match="Scan.ranges"):
        Scan(0.0, 0.1, 4.0, np.asarray(ranges, dtype=np.float32))


def test_a_scan_freezes_a_view_never_the_callers_array():
    mine = np.ones(4, dtype=np.float32)
    s = Scan(0.0, 0.1, 4.0, mine)
    assert mine.flags.writeable and not s.ranges.flags.writeable
    assert s.matches(ScanSpec(4, 0.0, 0.1, 4.0)) and not s.matches(ScanSpec(5, 0.0, 0.1, 4.0))
    np.testing.assert_allclose(s.angles(), [0.0, 0.1, 0.2, 0.3])


JUNK = [None, True, 0, -1, 1e15, -1e15, 2.5, "", "x", [], [None] * 5, [[]], {}, {"ranges": []}, [1] * 5000]


def test_any_scan_decodes_or_is_a_bad_frame():
    rng = np.random.default_rng(0)
    keys = ["angle_min", "angle_increment", "range_max", "ranges", "extra"]
    for _ in range(400):
        field = wire()
        for key in rng.choice(keys, size=rng.integers(1, 3), replace=False):
            field[str(key)] = JUNK[rng.integers(len(JUNK))]
        if rng.random() < 0.3:
            field["ranges"] = [JUNK[i] for i in rng.integers(0, 8, size=5)]
        try:
            got = protocol.decode_reply(reply_frames(field), expect_scan=SPEC).scan
        except BadFrameError:
            continue
        assert got is not None and got.beams == 5 and not np.isnan(got.ranges).any()
