"""Command-line options derived from config dataclasses, so each default and help text is written once.

A field becomes an option when its metadata has a help text (``opt(default, "help")``); its default and
type come from the dataclass, and ``--help`` shows the default. ``config_from_args`` builds the dataclass
back from the parsed namespace, so ``__post_init__`` validates the user's values with the same messages as
any other caller gets. Lean (standard library only): the robot board's entry uses it.
"""

from __future__ import annotations

import argparse
import dataclasses
import types
import typing
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")
_MISSING = dataclasses.MISSING


def opt(
    default: Any = _MISSING,
    help: str = "",  # noqa: A002 - the argparse name, on purpose
    *,
    flag: str | None = None,
    choices: Iterable[Any] | None = None,
    metavar: str | tuple[str, ...] | None = None,
    factory: Callable[[], Any] | None = None,
) -> Any:
    """A dataclass field that is also a command-line option (``--field-name`` unless ``flag`` says)."""
    meta = {"help": help, "flag": flag, "choices": tuple(choices) if choices else None, "metavar": metavar}
    if factory is not None:
        return dataclasses.field(default_factory=factory, metadata=meta)
    if default is _MISSING:
        return dataclasses.field(metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def _unwrap_optional(tp: Any) -> tuple[Any, bool]:
    args = typing.get_args(tp)
    if (typing.get_origin(tp) in (typing.Union, types.UnionType)) and type(None) in args:
        rest = [a for a in args if a is not type(None)]
        return rest[0], True
    return tp, False


def flag_of(f: dataclasses.Field) -> str:
    return f.metadata.get("flag") or "--" + f.name.replace("_", "-")


def add_config_arguments(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, cls: type, skip: Iterable[str] = ()
) -> None:
    """Add an option for every field of ``cls`` that has help metadata (except ``skip``)."""
    hints = typing.get_type_hints(cls)
    skipped = set(skip)
    for f in dataclasses.fields(cls):
        if "help" not in f.metadata or f.name in skipped:
            continue
        tp, _ = _unwrap_optional(hints[f.name])
        kwargs: dict[str, Any] = {"dest": f.name, "help": f.metadata["help"]}
        required = f.default is _MISSING and f.default_factory is _MISSING
        default = None if required else (f.default if f.default is not _MISSING else f.default_factory())
        if f.metadata.get("choices"):
            kwargs["choices"] = f.metadata["choices"]
        if f.metadata.get("metavar"):
            kwargs["metavar"] = f.metadata["metavar"]
        elif tp is not bool and not f.metadata.get("choices"):
            kwargs["metavar"] = flag_of(f).lstrip("-").replace("-", "_").upper()
        if tp is bool:
            kwargs["action"] = argparse.BooleanOptionalAction if default else "store_true"
            if default:
                kwargs["help"] += " (on by default)"
        else:
            origin = typing.get_origin(tp)
            if origin is tuple:
                inner = typing.get_args(tp)
                kwargs["type"] = inner[0]
                kwargs["nargs"] = "*" if len(inner) == 2 and inner[1] is Ellipsis else len(inner)
            else:
                kwargs["type"] = tp if tp in (int, float, str, Path) else str
            if required:
                kwargs["required"] = True
            elif default is not None and "(default" not in kwargs["help"]:  # the help may word it itself
                shown = " ".join(map(str, default)) if isinstance(default, tuple) else default
                kwargs["help"] += f" (default: {shown or 'none'})"
        if not required:
            kwargs["default"] = default
        parser.add_argument(flag_of(f), **kwargs)


def config_from_args(cls: type[T], args: argparse.Namespace, **extra: Any) -> T:
    """``cls`` built from the options ``add_config_arguments`` added, plus ``extra`` fields."""
    values = {}
    for f in dataclasses.fields(cls):
        if "help" in f.metadata and hasattr(args, f.name):
            value = getattr(args, f.name)
            values[f.name] = tuple(value) if isinstance(value, list) else value
    values.update(extra)
    return cls(**values)


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line (the problem and where to look), exit code 2."""

    def error(self, message: str) -> typing.NoReturn:
        self.exit(2, f"{self.prog}: {message} (see {self.prog} --help)\n")
