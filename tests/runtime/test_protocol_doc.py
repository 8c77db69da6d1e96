"""docs/PROTOCOL.md and the codec agree: every example in the document goes through the real codec."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from vtr.runtime import protocol
from vtr.runtime.hello import parse_hello
from vtr.runtime.scan import MAX_BEAMS, ScanSpec, spec_from_dict

DOC = Path(__file__).resolve().parents[2] / "docs" / "PROTOCOL.md"
BLOCK = re.compile(r"^```(json|json-refused)\n(.*?)^```", re.S | re.M)


def examples(kind: str) -> list[str]:
    return [body.strip() for k, body in BLOCK.findall(DOC.read_text()) if k == kind]


def frames_for(text: str) -> list[bytes]:
    header = json.loads(text)
    frames = [text.encode()]
    if header.get("ok") is True and header.get("cmd") in protocol.IMAGE_COMMANDS:
        frames.append(bytes(header["height"] * header["width"] * 3))
    return frames


def test_the_document_has_examples_of_every_command_and_reply_kind():
    headers = [json.loads(t) for t in examples("json")]
    requests = {h["cmd"] for h in headers if "ok" not in h}
    replies = {(h["cmd"], h["ok"]) for h in headers if "ok" in h}
    assert {"hello", "reset", "step", "stop"} <= requests
    assert {("hello", True), ("step", True), ("stop", True), ("step", False), (None, False)} <= replies
    assert len(examples("json-refused")) >= 3
    assert any("scan" in h for h in headers if h.get("cmd") == "hello" and "ok" in h)
    assert any("scan" in h for h in headers if h.get("cmd") in protocol.IMAGE_COMMANDS and "ok" in h)
    assert any("twist" in h for h in headers if h.get("cmd") == "hello" and "ok" in h)
    assert any("twist" in h for h in headers if h.get("cmd") in protocol.IMAGE_COMMANDS and "ok" in h)


def announced_scan() -> ScanSpec:
    """The scanner of the document's hello example that announces one (its image example matches it)."""
    hellos = [json.loads(t) for t in examples("json")]
    return spec_from_dict(next(h["scan"] for h in hellos if h.get("cmd") == "hello" and "scan" in h))


@pytest.mark.parametrize("text", examples("json"))
def test_every_example_decodes_through_the_codec(text):
    header = json.loads(text)
    frames = frames_for(text)
    if "ok" not in header:
        req = protocol.decode_request(frames)
        assert req.cmd == header["cmd"] and req.seq == header["seq"]
        return
    scan = header.get("scan")
    expect_scan = announced_scan() if scan is not None and header.get("cmd") != "hello" else None
    twist = header.get("twist") if header.get("cmd") != "hello" else None
    reply = protocol.decode_reply(
        frames,
        expect_cmd=header["cmd"],
        expect_seq=header["seq"],
        expect_scan=expect_scan,
        expect_twist=twist is not None,
    )
    if twist is not None:
        assert reply.twist == (twist["v"], twist["w"])
    assert reply.ok is header["ok"] and reply.session == header["session"]
    if reply.cmd == "hello":
        hello = parse_hello(reply)
        assert (
            hello.camera.width == header["camera"]["width"]
            and hello.limits.v_max == header["limits"]["v_max"]
        )
        assert (hello.scan is None) == (scan is None)
        assert hello.twist == (header.get("twist") or {}).get("source")
    elif expect_scan is not None:
        assert reply.scan is not None and reply.scan.beams == len(scan["ranges"]) == expect_scan.beams


@pytest.mark.parametrize("text", examples("json-refused"))
def test_every_refused_example_is_refused(text):
    with pytest.raises(protocol.ProtocolError):
        protocol.decode_request([text.encode()])


def test_the_documented_limits_are_the_codec_constants():
    doc = DOC.read_text()
    assert f"{protocol.MAX_HEADER_BYTES:,} bytes" in doc
    assert f"{protocol.MAX_MESSAGE_BYTES:,} bytes" in doc
    assert f"at most {protocol.MAX_DEPTH} levels" in doc
    assert f"1..{protocol.MAX_IMAGE_SIDE}" in doc
    assert f"1 to {protocol.MAX_SESSION_CHARS} characters" in doc
    assert f"1..{MAX_BEAMS}" in doc and f"cap of {MAX_BEAMS} beams" in doc
