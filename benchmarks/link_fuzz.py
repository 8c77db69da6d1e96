"""Fuzzed traffic for the link benchmarks: hostile requests for a server, hostile replies for a client.

Everything is drawn from one seeded ``random.Random``, so a run can be replayed exactly.
"""

from __future__ import annotations

import json
import random
from typing import Any

from vtr.benchmarks.link_robot import FakeRobot, good_reply
from vtr.runtime import protocol

FIELDS = ("proto", "version", "cmd", "seq", "stamp", "v", "w", "duration", "pose", "seed", "session")
REPLY_FIELDS = (
    "ok",
    "cmd",
    "seq",
    "session",
    "stamp",
    "encoding",
    "height",
    "width",
    "pose",
    "collided",
    "error",
)


def hostile_value(rng: random.Random) -> Any:
    """A JSON value chosen to break careless decoders (as a raw JSON text fragment)."""
    kind = rng.randrange(12)
    if kind == 0:
        return "9" * rng.randint(20, 5000)  # an integer beyond any float
    if kind == 1:
        n = rng.randint(17, 20000)  # deeper than any sane header
        return "[" * n + "]" * n
    if kind == 2:
        return rng.choice(["NaN", "Infinity", "-Infinity", "1e999", "-1e400", "1e16"])
    if kind == 3:
        return rng.choice(["1.0", "5.0", "true", "false", "null", "-1", "0"])
    if kind == 4:
        return json.dumps("".join(chr(rng.randint(0, 0x2FFF)) for _ in range(rng.randint(0, 40))))
    if kind == 5:
        return json.dumps({"x": rng.random(), "y": "a", "yaw": [1]})
    if kind == 6:
        return json.dumps([rng.random() for _ in range(rng.randint(0, 50))])
    if kind == 7:
        return str(rng.uniform(-1e6, 1e6))
    if kind == 8:
        return json.dumps("x" * rng.randint(0, 70000))  # may push the header past its cap
    if kind == 9:
        return str(rng.randint(-(2**70), 2**70))
    if kind == 10:
        return json.dumps({str(i): {"a": [i]} for i in range(rng.randint(0, 300))})
    return json.dumps(rng.choice([0.1, -0.3, 0.0, 10.0, 1e-9]))


def with_fields(header: dict[str, Any], names: tuple[str, ...], rng: random.Random) -> bytes:
    """``header`` as JSON text with one to three fields replaced by hostile raw fragments."""
    text = json.dumps(header)[:-1]
    for name in rng.sample(names, rng.randint(1, 3)):
        text += f',"{name}":{hostile_value(rng)}'
    return (text + "}").encode()


def fuzz_request(rng: random.Random, seq: int) -> tuple[list[bytes], bool]:
    """(frames, whether ZeroMQ itself will cut the peer off for size: then no reply comes)."""
    cmd = rng.choice(protocol.COMMANDS)
    base: dict[str, Any] = {"proto": "vtr-sim", "version": 1, "cmd": cmd, "seq": seq, "stamp": 1.0}
    if cmd == "step":
        base.update(v=rng.uniform(-0.5, 0.5), w=rng.uniform(-1, 1), duration=0.1)
    kind = rng.randrange(10)
    if kind == 0:
        return [rng.randbytes(rng.randint(0, 200))], False
    if kind == 1:
        return [json.dumps(base).encode()], False  # valid: the server keeps doing real work
    if kind == 2:
        raw = json.dumps(base).encode()
        return [raw[: rng.randint(0, len(raw))]], False
    if kind == 3:
        extra = [rng.randbytes(rng.randint(0, 100_000)) for _ in range(rng.randint(1, 3))]
        return [json.dumps(base).encode(), *extra], False
    if kind == 4 and rng.random() < 0.05:
        return [json.dumps(base).encode(), bytes(5 * 1024 * 1024)], True  # past ZMQ_MAXMSGSIZE
    if kind == 5:
        return [b"\xff\xfe" + json.dumps(base).encode()], False
    return [with_fields(base, FIELDS, rng)], False


def fuzz_reply(
    rng: random.Random, good: list[bytes], previous: list[bytes] | None
) -> tuple[str, list[list[bytes]]]:
    """A fault and the replies that carry it, built from the correct reply ``good``.

    Kinds: garbage, mutated, truncated, wrong_shape, future_stamp, stale_stamp, future_seq, duplicate,
    stale_then_good, empty (a message of one empty frame), silent, oversized, late (sent with the
    next request's reply).
    """
    header = json.loads(good[0])
    kind = rng.choice(
        [
            "garbage",
            "mutated",
            "mutated",
            "mutated",
            "truncated",
            "wrong_shape",
            "future_stamp",
            "stale_stamp",
            "future_seq",
            "duplicate",
            "stale_then_good",
            "empty",
            "silent",
            "oversized",
            "late",
        ]
    )
    if kind == "garbage":
        return kind, [[rng.randbytes(rng.randint(0, 300))]]
    if kind == "mutated":
        return kind, [[with_fields(header, REPLY_FIELDS, rng), *good[1:]]]
    if kind == "truncated" and len(good) == 2:
        return kind, [[good[0], good[1][: rng.randint(0, len(good[1]) - 1)]]]
    if kind == "wrong_shape" and len(good) == 2:
        header.update(height=header["height"] * 2)
        return kind, [[json.dumps(header).encode(), good[1] * 2]]
    if kind == "future_stamp":
        header.update(stamp=header["stamp"] + rng.choice([1e3, 1e6, 1e9]))
        return kind, [[json.dumps(header).encode(), *good[1:]]]
    if kind == "stale_stamp":
        header.update(stamp=-1.0)
        return kind, [[json.dumps(header).encode(), *good[1:]]]
    if kind == "future_seq":
        header.update(seq=header["seq"] + rng.randint(1, 5))
        return kind, [[json.dumps(header).encode(), *good[1:]]]
    if kind == "duplicate":
        return kind, [good, good]
    if kind == "stale_then_good" and previous is not None:
        return kind, [previous, good]
    if kind == "empty":
        return kind, [[], good]
    if kind == "silent":
        return kind, []
    if kind == "oversized":
        return kind, [[good[0], bytes(5 * 1024 * 1024)]]
    if kind == "late":
        return kind, []
    return "mutated", [[with_fields(header, REPLY_FIELDS, rng), *good[1:]]]


#: Not a bad frame to the client: skipped by seq matching, or a mutation that left the reply valid.
HARMLESS = ("duplicate", "stale_then_good", "mutated_but_valid")


def _acceptable(frames: list[bytes], good: list[bytes], req: protocol.Request) -> bool:
    """Whether a mutated reply still is the correct answer to ``req`` (same stamp, session and pose)."""
    try:
        got = protocol.decode_reply(frames, expect_cmd=req.cmd, expect_seq=req.seq, expect_shape=(16, 16))
    except protocol.ProtocolError:
        return False
    want = protocol.decode_reply(good)
    return got.ok and (got.stamp, got.session, got.pose) == (want.stamp, want.session, want.pose)


class FaultInjector:
    """A FakeRobot behaviour: the correct reply, or with probability ``p_fault`` (until ``n`` faults) a
    fuzzed one. ``faults`` lists (index of the request in the robot's arrivals, kind); ``dirty`` turns
    true when a fault that is not ``harmless`` (or a late reply) was sent since the caller cleared it."""

    def __init__(self, rng: random.Random, n: int, p_fault: float, harmless: tuple[str, ...]) -> None:
        self.rng, self.n, self.p_fault, self.harmless = rng, n, p_fault, harmless
        self.faults: list[tuple[int, str]] = []
        self.dirty = False
        self._late: list[bytes] | None = None
        self._previous: list[bytes] | None = None

    def __call__(self, robot: FakeRobot, req: protocol.Request) -> list[list[bytes]]:
        good = good_reply(robot, req)
        out: list[list[bytes]] = []
        if self._late is not None:
            out.append(self._late)
            self._late, self.dirty = None, True
        if len(self.faults) < self.n and self.rng.random() < self.p_fault:
            kind, replies = fuzz_reply(self.rng, good, self._previous)
            if kind == "mutated" and _acceptable(replies[0], good, req):
                kind = "mutated_but_valid"  # e.g. a changed field the reply's kind ignores
            self.faults.append((len(robot.arrivals) - 1, kind))
            self.dirty = self.dirty or kind not in self.harmless
            self._late = good if kind == "late" else None
            out += replies
        else:
            out.append(good)
        self._previous = good
        return out

    def kinds(self) -> dict[str, int]:
        counts: dict[str, int] = {}
        for _, kind in self.faults:
            counts[kind] = counts.get(kind, 0) + 1
        return dict(sorted(counts.items()))
