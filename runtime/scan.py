"""A planar range scan (like ROS's ``sensor_msgs/LaserScan``): the typed value and its wire form.

The robot announces its scanner in ``hello`` (:class:`ScanSpec`: beam count, angles, range, mounting) and
may add a reading to every image reply; docs/PROTOCOL.md, "Range scan", is the contract. Angles follow
REP-103: 0 is straight ahead, counter-clockwise positive, radians. A beam that saw nothing within
``range_max`` is ``+inf`` in a :class:`Scan` (``null`` on the wire, as is a value above ``range_max``).

Wire form: the ranges travel in the JSON header, not in an extra frame. A header field is what every
version-1 peer already ignores when it does not know it, while an extra frame makes an older decoder
refuse the whole reply (an image reply is exactly two frames), so a robot with a scanner keeps working
with every client. The price is parsing: about 0.1 ms per reply for 181 beams on the development
machine, 0.5 ms for :data:`MAX_BEAMS`; hence the cap (one 0.25 deg 270 deg scanner), and our simulator
sends millimetres.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from vtr.runtime.wire_json import BadFrameError, integer, number, show

#: Most beams a scan may have (a 270 deg scanner at 0.25 deg); headers stay well below their size limit.
MAX_BEAMS = 1081
#: Largest ``range_max`` accepted, metres.
MAX_SCAN_RANGE = 100.0
#: Largest mounting offset ``x_m`` accepted, metres (either way from the robot's centre).
MAX_MOUNT_OFFSET = 5.0
#: A reply's angles and range_max must equal the announcement within this (float32 rounding in bridges).
MATCH_TOLERANCE = 1e-5
_TWO_PI = 2.0 * math.pi
_NUMBER_TYPES = frozenset((float, int, type(None)))


@dataclass(frozen=True)
class ScanSpec:
    """The scanner a robot announces in ``hello``; every reply's scan must match it."""

    beams: int
    angle_min: float  # rad, bearing of beam 0 (0 ahead, counter-clockwise positive)
    angle_increment: float  # rad between beams (negative: the scanner sweeps clockwise)
    range_max: float  # m, farther than this counts as nothing seen
    x_m: float = 0.0  # m, scanner forward of the robot's centre (base_link); on its centreline, level

    def to_dict(self) -> dict[str, float | int]:
        return {
            "beams": self.beams,
            "angle_min": self.angle_min,
            "angle_increment": self.angle_increment,
            "range_max": self.range_max,
            "x_m": self.x_m,
        }


@dataclass(frozen=True)
class Scan:
    """One reading. ``ranges`` (beams,) float32, read-only: metres in [0, range_max], +inf where nothing
    was seen; beam i looks at ``angle_min + i * angle_increment`` from the scanner, which sits ``x_m``
    ahead of the robot's centre."""

    angle_min: float
    angle_increment: float
    range_max: float
    ranges: np.ndarray
    x_m: float = 0.0

    def __post_init__(self) -> None:
        r = np.asarray(self.ranges, dtype=np.float32)
        if r.ndim != 1 or r.size == 0:
            raise ValueError(f"Scan.ranges must be a non-empty 1-D array, got shape {r.shape}")
        ok = (r >= 0) & (r <= np.float32(self.range_max))
        ok |= r == np.inf
        if not ok.all():
            i = int(np.argmin(ok))
            raise ValueError(f"Scan.ranges[{i}] = {r[i]} is not in [0, range_max={self.range_max}] nor +inf")
        if r is self.ranges:
            r = r.view()  # freeze a view, never the caller's array
        r.flags.writeable = False
        object.__setattr__(self, "ranges", r)

    @property
    def beams(self) -> int:
        return int(self.ranges.size)

    def angles(self) -> np.ndarray:
        """(beams,) bearing of each beam from the scanner, radians."""
        return self.angle_min + self.angle_increment * np.arange(self.ranges.size)

    def directions(self) -> np.ndarray:
        """(2, beams) read-only unit vector of each beam (cos, sin of its bearing), shared by every scan of
        the same geometry."""
        return _directions(self.angle_min, self.angle_increment, self.ranges.size)

    def matches(self, spec: ScanSpec) -> bool:
        return (
            self.beams == spec.beams
            and _close(self.angle_min, spec.angle_min)
            and _close(self.angle_increment, spec.angle_increment)
            and _close(self.range_max, spec.range_max)
        )


@functools.lru_cache(maxsize=8)  # keyed by the geometry's values: a robot has one scanner
def _directions(angle_min: float, angle_increment: float, beams: int) -> np.ndarray:
    angles = angle_min + angle_increment * np.arange(beams)
    out = np.stack([np.cos(angles), np.sin(angles)])
    out.flags.writeable = False
    return out


def _close(a: float, b: float) -> bool:
    return abs(a - b) <= MATCH_TOLERANCE * max(1.0, abs(b))


def spec_from_dict(d: Any, err: type[ValueError] = BadFrameError, where: str = "scan.") -> ScanSpec:
    """Read the ``hello`` announcement ``{"beams", "angle_min", "angle_increment", "range_max", "x_m"?}``."""
    if not isinstance(d, dict):
        raise err(f"hello field {where.rstrip('.')!r} must be an object, got {show(d)}")
    beams = integer(d, "beams", err, where)
    if not 1 <= beams <= MAX_BEAMS:
        raise err(f"field {where}beams must be in 1..{MAX_BEAMS}, got {beams}")
    angle_min, increment = number(d, "angle_min", err, where), number(d, "angle_increment", err, where)
    if abs(angle_min) > _TWO_PI:
        raise err(f"field {where}angle_min must be in [-2 pi, 2 pi] rad, got {angle_min}")
    if increment == 0 or abs(increment) * (beams - 1) > _TWO_PI + 1e-9:
        raise err(
            f"field {where}angle_increment must be non-zero and the {beams} beams span at most 2 pi rad, "
            f"got {increment}"
        )
    range_max = number(d, "range_max", err, where)
    if not 0 < range_max <= MAX_SCAN_RANGE:
        raise err(f"field {where}range_max must be in (0, {MAX_SCAN_RANGE:g}] m, got {range_max}")
    x_m = number(d, "x_m", err, where) if d.get("x_m") is not None else 0.0
    if abs(x_m) > MAX_MOUNT_OFFSET:
        raise err(f"field {where}x_m must be within +-{MAX_MOUNT_OFFSET:g} m, got {x_m}")
    return ScanSpec(beams, angle_min, increment, range_max, x_m)


def scan_from_wire(d: Any, spec: ScanSpec, err: type[ValueError] = BadFrameError) -> Scan:
    """A reply's ``scan`` object, checked against the announcement ``spec``; ``err`` names the field."""
    if not isinstance(d, dict):
        raise err(f"reply field 'scan' must be an object or null, got {show(d)}")
    for key in ("angle_min", "angle_increment", "range_max"):
        value = number(d, key, err, "scan.")
        if not _close(value, getattr(spec, key)):
            raise err(f"reply field 'scan.{key}' is {value}, but hello announced {getattr(spec, key)}")
    ranges = d.get("ranges")
    if not isinstance(ranges, list):
        raise err(f"reply field 'scan.ranges' must be a list of numbers or nulls, got {show(ranges)}")
    if len(ranges) != spec.beams:
        raise err(
            f"reply field 'scan.ranges' has {len(ranges)} values, but hello announced {spec.beams} beams"
        )
    if not set(map(type, ranges)).issubset(_NUMBER_TYPES):
        i = next(i for i, r in enumerate(ranges) if type(r) not in _NUMBER_TYPES)
        raise err(f"reply field 'scan.ranges[{i}]' must be a number or null, got {show(ranges[i])}")
    values = np.array(ranges, dtype=np.float64)  # null -> NaN; numbers are finite (the JSON parser's rule)
    if (values < 0).any():
        i = int(np.argmax(values < 0))
        raise err(f"reply field 'scan.ranges[{i}]' must be >= 0 m (null: nothing seen), got {ranges[i]}")
    nothing = np.isnan(values)
    nothing |= values > spec.range_max
    values[nothing] = np.inf
    return Scan(spec.angle_min, spec.angle_increment, spec.range_max, values.astype(np.float32), spec.x_m)


def scan_to_wire(scan: Scan) -> dict[str, Any]:
    """The reply's ``scan`` object: ranges in millimetres' precision, null where nothing was seen."""
    ranges = np.round(scan.ranges.astype(np.float64), 3).tolist()
    return {
        "angle_min": scan.angle_min,
        "angle_increment": scan.angle_increment,
        "range_max": scan.range_max,
        "ranges": [None if r == math.inf else r for r in ranges],
    }
