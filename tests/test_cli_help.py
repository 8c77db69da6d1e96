"""Every command's --help shows the default of every option that has one: a user reads what happens when they
leave a flag out without opening the code."""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Iterator, Mapping

from vtr.cli import COMMANDS
from vtr.runtime.cliargs import OneLineParser
from vtr.runtime.commands import ROBOT_COMMANDS, Command


def _parsers(prefix: str, commands: Mapping[str, Command]) -> Iterator[tuple[str, argparse.ArgumentParser]]:
    for name, command in commands.items():
        module = importlib.import_module(command.module)
        if command.subcommands:
            yield from _parsers(f"{prefix} {name}", module.COMMANDS)
            continue
        parser = OneLineParser(prog=f"{prefix} {name}")
        getattr(module, command.add)(parser)
        yield f"{prefix} {name}", parser


def _has_default(action: argparse.Action) -> bool:
    """An option whose value, when the flag is left out, is worth saying (a plain on/off flag's is not)."""
    if not action.option_strings or action.default in (None, argparse.SUPPRESS):
        return False
    flag = action.nargs == 0 and not isinstance(action, argparse.BooleanOptionalAction)
    return not (flag and action.default is False)


def _undocumented(parsers: Iterator[tuple[str, argparse.ArgumentParser]]) -> list[str]:
    missing = []
    for prog, parser in parsers:
        formatter = parser._get_formatter()
        for action in parser._actions:
            if not _has_default(action):
                continue
            text = formatter._expand_help(action) if action.help else ""
            if "(default" not in text and "by default" not in text or "(default: )" in text:
                missing.append(f"{prog} {action.option_strings[-1]} (default {action.default!r}): {text!r}")
    return missing


def test_every_help_shows_each_options_default() -> None:
    missing = _undocumented(_parsers("vtr", COMMANDS)) + _undocumented(_parsers("vtr-robot", ROBOT_COMMANDS))
    assert not missing, "options whose --help hides their default:\n" + "\n".join(missing)


def test_the_walk_sees_a_hidden_default() -> None:
    parser = OneLineParser(prog="x")
    parser.add_argument("--frames", type=int, default=7024, help="frames to record")
    parser.add_argument("--seed", type=int, default=0, help="the seed (default: 0)")
    parser.add_argument("--quiet", action="store_true", help="say less")
    assert [m.split(" (")[0] for m in _undocumented(iter([("x", parser)]))] == ["x --frames"]
