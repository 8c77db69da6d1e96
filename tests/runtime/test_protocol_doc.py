"""docs/PROTOCOL.md and the codec agree: every example in the document goes through the real codec."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from vtr.runtime import protocol
from vtr.runtime.hello import parse_hello

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


@pytest.mark.parametrize("text", examples("json"))
def test_every_example_decodes_through_the_codec(text):
    header = json.loads(text)
    frames = frames_for(text)
    if "ok" not in header:
        req = protocol.decode_request(frames)
        assert req.cmd == header["cmd"] and req.seq == header["seq"]
        return
    reply = protocol.decode_reply(frames, expect_cmd=header["cmd"], expect_seq=header["seq"])
    assert reply.ok is header["ok"] and reply.session == header["session"]
    if reply.cmd == "hello":
        hello = parse_hello(reply)
        assert (
            hello.camera.width == header["camera"]["width"]
            and hello.limits.v_max == header["limits"]["v_max"]
        )


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
