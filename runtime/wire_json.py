"""Bounded JSON for the wire: whatever the bytes, parsing returns a value or raises :class:`ProtocolError`.

A hostile or broken peer controls every byte of a header, so nesting depth, integer size and float range
are checked before or while Python builds objects: a 400-digit integer never becomes a Python int, a
header nested 1,000 deep never reaches the recursive parser, ``NaN``/``Infinity`` are refused.
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

#: A header larger than this is refused before parsing.
MAX_HEADER_BYTES = 64 * 1024
#: Deepest JSON nesting accepted in a header (objects and arrays together).
MAX_DEPTH = 16
#: Integers on the wire lie in [-MAX_INT, MAX_INT] (exact in a double: what every JSON library can read).
MAX_INT = 2**53
#: Any number on the wire has |x| <= MAX_ABS_NUMBER.
MAX_ABS_NUMBER = 1e15
#: Longest session token.
MAX_SESSION_CHARS = 64


class ProtocolError(ValueError):
    """A message that does not follow this protocol; the message says what is wrong."""


class BadFrameError(ProtocolError):
    """A reply the client must reject (counted by the client, never fed to the network)."""


_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"')
_NOT_BRACKET = re.compile(rb"[^\[\]{}]")


def _too_deep(raw: bytes) -> bool:
    """Whether a JSON text nests objects/arrays deeper than MAX_DEPTH, brackets inside strings ignored."""
    if raw.count(b"{") + raw.count(b"[") <= MAX_DEPTH:  # no deeper than its opening brackets: done
        return False  # (every header of this protocol: the scan below is for hostile ones)
    depth = 0
    for ch in _NOT_BRACKET.sub(b"", _STRING.sub(b"", raw)):
        depth += 1 if ch in b"[{" else -1
        if depth > MAX_DEPTH:
            return True
    return False


def _parse_int(text: str) -> int:
    # The length is checked before int(): a 400-digit integer never becomes a Python int.
    if len(text) <= 17:  # "-" and 16 digits; 2**53 has 16
        value = int(text)
        if -MAX_INT <= value <= MAX_INT:
            return value
    raise ValueError(f"integer {text[:24]}{'...' if len(text) > 24 else ''} is out of range (|n| <= 2**53)")


def _parse_float(text: str) -> float:
    value = float(text)
    if -MAX_ABS_NUMBER <= value <= MAX_ABS_NUMBER:  # NaN and +-inf fail the comparison
        return value
    raise ValueError(f"number {text[:24]} is out of range (|x| <= {MAX_ABS_NUMBER:g})")


def _reject_constant(token: str) -> float:
    raise ValueError(f"non-finite number {token} in JSON")


#: One decoder for every header (json.loads with hooks would build a new one per call).
_DECODER = json.JSONDecoder(parse_int=_parse_int, parse_float=_parse_float, parse_constant=_reject_constant)
_SCAN = _DECODER.scan_once


def parse_json(raw: bytes, err: type[ProtocolError] = ProtocolError) -> Any:
    """Bytes -> a JSON value with bounded depth and numbers; anything else raises ``err``."""
    if len(raw) > MAX_HEADER_BYTES:
        raise err(f"header frame of {len(raw)} bytes exceeds the limit of {MAX_HEADER_BYTES} bytes")
    if _too_deep(raw):
        raise err(f"JSON header nested deeper than {MAX_DEPTH} levels")
    try:
        text = raw.decode("utf-8")
        if text.startswith("\ufeff"):  # as json.loads: a byte-order mark is not JSON
            raise ValueError("Unexpected UTF-8 BOM (decode using utf-8-sig)")
        # A text that is one value from its first character to its last (every header we send) is what
        # decode() returns, without its whitespace scans (~1.3 us, twice a control step); anything else,
        # and every malformed text, takes decode() for its result and its message.
        try:
            value, end = _SCAN(text, 0)
        except StopIteration:
            end = -1
        return value if end == len(text) else _DECODER.decode(text)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:  # JSONDecodeError is a ValueError
        raise err(f"malformed JSON header: {exc}") from None


def show(value: Any) -> str:
    """A short repr for error messages (a hostile peer may send a 60 KiB string)."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def number(obj: dict[str, Any], key: str, err: type[ProtocolError] = ProtocolError, where: str = "") -> float:
    """``obj[key]`` as a float: a JSON number (not a bool), finite, |x| <= MAX_ABS_NUMBER."""
    if key not in obj:
        raise err(f"missing field {where}{key!r}")
    value = obj[key]
    if type(value) not in (int, float):
        raise err(f"field {where}{key!r} must be a number, got {show(value)}")
    if not (math.isfinite(value) and abs(value) <= MAX_ABS_NUMBER):
        raise err(f"field {where}{key!r} is out of range, got {show(value)}")
    return float(value)


def integer(obj: dict[str, Any], key: str, err: type[ProtocolError] = ProtocolError, where: str = "") -> int:
    """``obj[key]`` as an int: a JSON integer only (``5.0`` and ``true`` are refused), |n| <= MAX_INT."""
    if key not in obj:
        raise err(f"missing field {where}{key!r}")
    value = obj[key]
    if type(value) is not int:
        raise err(f"field {where}{key!r} must be an integer, got {show(value)}")
    if abs(value) > MAX_INT:
        raise err(f"field {where}{key!r} is out of range, got {show(value)}")
    return value


def session_field(obj: dict[str, Any], err: type[ProtocolError], required: bool) -> str | None:
    """``obj["session"]``: a string of 1..MAX_SESSION_CHARS characters (None when absent and not required)."""
    value = obj.get("session")
    if value is None and not required:
        return None
    if not isinstance(value, str) or not 0 < len(value) <= MAX_SESSION_CHARS:
        raise err(f"field 'session' must be a string of 1..{MAX_SESSION_CHARS} characters, got {show(value)}")
    return value


def pose_field(value: Any, err: type[ProtocolError], key: str = "pose") -> tuple[float, float, float]:
    """A pose object ``{"x", "y", "yaw"}`` as a tuple of bounded numbers."""
    if not isinstance(value, dict):
        raise err(f"field {key!r} must be an object {{'x', 'y', 'yaw'}}, got {show(value)}")
    return tuple(number(value, k, err, where=f"{key}.") for k in ("x", "y", "yaw"))  # type: ignore[return-value]


def jsonable(value: Any) -> Any:
    """The simulator's info() as plain JSON (dataclasses/tuples/numpy scalars flattened, NaN -> None)."""

    def default(obj: Any) -> Any:
        if hasattr(obj, "__dataclass_fields__"):
            return {k: getattr(obj, k) for k in obj.__dataclass_fields__}
        if hasattr(obj, "tolist"):
            return obj.tolist()
        return str(obj)

    def clean(obj: Any) -> Any:
        if isinstance(obj, float) and not math.isfinite(obj):
            return None
        if isinstance(obj, dict):
            return {str(k): clean(v) for k, v in obj.items()}
        if isinstance(obj, list):
            return [clean(v) for v in obj]
        return obj

    return clean(json.loads(json.dumps(value, default=default)))


__all__ = [
    "MAX_ABS_NUMBER",
    "MAX_DEPTH",
    "MAX_HEADER_BYTES",
    "MAX_INT",
    "MAX_SESSION_CHARS",
    "BadFrameError",
    "ProtocolError",
    "integer",
    "jsonable",
    "number",
    "parse_json",
    "pose_field",
    "session_field",
    "show",
]
