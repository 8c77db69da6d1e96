"""parse_json's fast path (the scanner called directly) answers exactly as json's decode() path: the same
value for every text, the same refusal and message for every malformed one."""

from __future__ import annotations

import json

from hypothesis import given, settings
from hypothesis import strategies as st

from vtr.runtime.wire_json import _DECODER, ProtocolError, _too_deep, parse_json

_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**60), 2**60)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=8,
)
_space = st.sampled_from(["", " ", "\n", "\t ", "\r\n"])


def _reference(raw: bytes) -> tuple[str, object]:
    """What parse_json answered before its fast path: decode() on the text."""
    try:
        return "ok", _DECODER.decode(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        return "error", f"malformed JSON header: {exc}"


def _answer(raw: bytes) -> tuple[str, object]:
    try:
        return "ok", parse_json(raw)
    except ProtocolError as exc:
        return "error", str(exc)


@settings(max_examples=300, deadline=None)
@given(_values, _space, _space, st.sampled_from(["", "x", ",", "}", "1", "[]"]))
def test_a_json_text_with_any_whitespace_or_trailer_gets_decodes_answer(value, before, after, trailer):
    raw = (before + json.dumps(value, allow_nan=False) + after + trailer).encode()
    assert _answer(raw) == _reference(raw)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=40))
def test_any_bytes_get_decodes_answer(raw):
    if raw.startswith(b"\xef\xbb\xbf") or _too_deep(raw):
        return  # the BOM and the depth scan answer before decode() in both versions
    assert _answer(raw) == _reference(raw)
