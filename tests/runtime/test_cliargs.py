"""Options derived from config dataclasses: each default written once and shown, values validated by the
dataclass, usage errors in one line; and the endpoint check."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from vtr.runtime.address import check_endpoint
from vtr.runtime.cliargs import OneLineParser, add_config_arguments, config_from_args, opt


@dataclass
class Example:
    name: str = opt(help="a required name")
    count: int = opt(3, "how many")
    ratio: float | None = opt(None, "a ratio; default: derived")
    fast: bool = opt(False, "go fast")
    check: bool = opt(True, "check things")
    sizes: tuple[int, ...] = opt((1, 2), "sizes")
    mode: str = opt("a", "the mode", choices=("a", "b"))
    hidden: int = 7  # no help: not an option

    def __post_init__(self) -> None:
        if self.count < 1:
            raise ValueError(f"--count must be >= 1, got {self.count}")


def _parser() -> OneLineParser:
    parser = OneLineParser(prog="demo")
    add_config_arguments(parser, Example)
    return parser


def test_defaults_are_shown_and_values_round_trip() -> None:
    text = _parser().format_help()
    assert "how many (default: 3)" in text and "sizes (default: 1 2)" in text and "--hidden" not in text
    assert "--no-check" in text and "(default: a)" in text
    cfg = config_from_args(Example, _parser().parse_args(["--name", "x", "--sizes", "4", "5", "--no-check"]))
    assert cfg == Example(name="x", count=3, ratio=None, fast=False, check=False, sizes=(4, 5), mode="a")


def test_the_dataclass_validates_and_usage_errors_are_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ValueError, match="--count"):
        config_from_args(Example, _parser().parse_args(["--name", "x", "--count", "0"]))
    with pytest.raises(SystemExit) as exc:
        _parser().parse_args(["--count", "3"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--name" in err and "demo --help" in err


@pytest.mark.parametrize(
    ("endpoint", "bind", "words"),
    [
        ("http://127.0.0.1:5601", False, "http://"),
        ("tcp://127.0.0.1", False, "no port"),
        ("127.0.0.1:5555", False, "no transport"),
        ("tcp://127.0.0.1:0", False, "1..65535"),
        ("tcp://127.0.0.1:*", False, "1..65535"),
        ("ipc://", False, "names no"),
    ],
)
def test_malformed_endpoints_are_refused(endpoint: str, bind: bool, words: str) -> None:
    with pytest.raises(ValueError, match=words.replace(".", r"\.").replace("*", r"\*")):
        check_endpoint(endpoint, bind=bind)


def test_good_endpoints_pass() -> None:
    for endpoint in (
        "tcp://127.0.0.1:5555",
        "tcp://localhost:1",
        "tcp://[::1]:5555",
        "ipc:///tmp/x",
        "inproc://a",
    ):
        assert check_endpoint(endpoint) == endpoint
    assert check_endpoint("tcp://127.0.0.1:*", bind=True) == "tcp://127.0.0.1:*"
