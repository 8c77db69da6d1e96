"""The `vtr` entry point: every command and subcommand is listed and explains itself with --help."""

from __future__ import annotations

import importlib

import pytest

from vtr import cli
from vtr.runtime.commands import Command


def _every_command() -> list[tuple[list[str], Command]]:
    """(argv prefix, command) for every command and, through the tables, every subcommand."""
    out, todo = [], [([name], c) for name, c in cli.COMMANDS.items()]
    while todo:
        argv, command = todo.pop(0)
        out.append((argv, command))
        if command.subcommands:
            table = importlib.import_module(command.module).COMMANDS
            todo += [([*argv, name], c) for name, c in table.items()]
    return out


def test_top_level_help_lists_every_command(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    for name in cli.COMMANDS:
        assert f"  {name} " in out


def test_no_command_prints_the_list_and_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main([]) == 2
    assert "usage: vtr COMMAND" in capsys.readouterr().err
    assert cli.main(["sim"]) == 2
    assert "usage: vtr sim COMMAND" in capsys.readouterr().err


def test_unknown_command_is_an_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["fly"]) == 2
    assert "unknown command 'fly'" in capsys.readouterr().err
    assert cli.main(["bench", "fly"]) == 2
    assert "vtr bench: unknown command 'fly'" in capsys.readouterr().err


def test_bench_help_lists_each_subcommand_with_a_line(capsys: pytest.CaptureFixture[str]) -> None:
    from vtr.benchmarks.cli import COMMANDS

    assert cli.main(["bench", "--help"]) == 0
    lines = capsys.readouterr().out.splitlines()
    for name, command in COMMANDS.items():
        assert any(line.split() == [name, *command.summary.split()] for line in lines), name


@pytest.mark.parametrize("argv", [a for a, _ in _every_command()], ids=" ".join)
def test_every_command_and_subcommand_has_help(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    try:
        code = cli.main([*argv, "--help"])  # a table of subcommands answers itself
    except SystemExit as exc:  # argparse's --help
        code = int(exc.code or 0)
    assert code == 0
    assert f"usage: vtr {' '.join(argv)}" in capsys.readouterr().out
