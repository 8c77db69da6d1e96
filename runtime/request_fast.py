"""The fast path of ``protocol.encode_request``: the requests a client sends every control step (``step``,
``stop``, ``observe``, ``hello``) built from a byte template, checked on the Python values.

The general path serialises a dict with ``json.dumps`` and then decodes the result again with the
server's own ``decode_request`` (so a client never sends what a server would refuse); that round trip
was half the protocol's cost per control step. Here each value is checked against exactly what that
decode would accept, and anything this module is not sure about (a field it does not know, a numpy
scalar, a value out of range, a ``reset``) returns None so the caller takes the general path, which also
words the error. The bytes are identical to the general path's (``json.dumps`` writes a float with
``float.__repr__``, keys in insertion order, ASCII only); tests/runtime/test_request_fast.py checks
both properties against the general path.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any, Protocol

from vtr.runtime.wire_json import MAX_ABS_NUMBER, MAX_INT


class _Limits(Protocol):
    v_max: float
    w_max: float
    max_duration: float


def _plain_number(value: Any) -> bool:
    """What ``wire_json.number`` accepts after a JSON round trip: an exact int/float (not bool), in range.

    NaN fails the comparison, so does +-inf."""
    return (type(value) is float or type(value) is int) and -MAX_ABS_NUMBER <= value <= MAX_ABS_NUMBER


class RequestTemplates:
    """Header prefixes per command, and the session fragments seen so far (one or two per run)."""

    #: Commands whose only extra fields are the ones below; ``reset`` (pose, seed) takes the general path.
    FAST_COMMANDS = ("hello", "observe", "step", "stop")
    STEP_FIELDS = ("v", "w", "duration")

    def __init__(self, proto: str, version: int, max_session_chars: int) -> None:
        self._prefix = {
            cmd: json.dumps({"proto": proto, "version": version, "cmd": cmd}, separators=(",", ":"))[:-1]
            + ',"seq":'
            for cmd in self.FAST_COMMANDS
        }
        self._max_session = max_session_chars
        self._sessions: dict[str, str] = {}

    def _session(self, value: Any) -> str | None:
        fragment = self._sessions.get(value) if type(value) is str else None
        if fragment is None:
            if type(value) is not str or not 0 < len(value) <= self._max_session:
                return None
            fragment = ',"session":' + json.dumps(value)
            if len(self._sessions) < 16:  # a client talks to one server session at a time
                self._sessions[value] = fragment
        return fragment

    def header(
        self, cmd: str, seq: Any, stamp: Any, limits: _Limits | None, fields: Mapping[str, Any]
    ) -> bytes | None:
        """The encoded header, or None: take the general path."""
        prefix = self._prefix.get(cmd)
        if prefix is None or type(seq) is not int or not 0 <= seq <= MAX_INT:
            return None
        parts = [prefix, repr(seq)]
        if stamp is not None:
            if not _plain_number(stamp):
                return None
            parts += (',"stamp":', repr(stamp))
        step = cmd == "step"
        seen = 0
        for key, value in fields.items():
            if value is None:
                continue
            if key == "session":
                fragment = self._session(value)
                if fragment is None:
                    return None
                parts.append(fragment)
            elif step and key in self.STEP_FIELDS and _plain_number(value):
                parts += (',"', key, '":', repr(value))
                seen += 1
            else:
                return None
        if step:
            if seen != 3 or not fields["duration"] > 0:
                return None
            if limits is not None and not (
                abs(fields["v"]) <= limits.v_max
                and abs(fields["w"]) <= limits.w_max
                and fields["duration"] <= limits.max_duration
            ):
                return None
        parts.append("}")
        return "".join(parts).encode("ascii")
