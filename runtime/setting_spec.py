"""One setting of the schema (``runtime.settings`` declares them all): where it lives in the config file,
what it takes, what it means, and the check every value from a file or a flag goes through."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


#: Marks a setting with no default: a flag or the config file must give it.
REQUIRED: Any = _Required()


@dataclass(frozen=True)
class Setting:
    """One setting: where it lives, what it takes, what it means."""

    section: str  # the config file's table
    key: str  # its key there
    kind: type  # str, int, float or bool
    help: str  # one line
    default: Any = REQUIRED  # None: off / derived (see default_text)
    unit: str = ""  # "s", "m", ...
    choices: tuple[str, ...] = ()
    low: float | None = None
    high: float | None = None
    low_open: bool = False  # (low, high] instead of [low, high]
    path: bool = False  # a file path: relative ones in the config file are relative to the file
    takes: str = ""  # what a text setting takes, in words (default: "text", or "a file path")
    flag: str = ""  # default: --key
    file_only: bool = False  # no flag: a tuning knob of the robot's board, set once in its config file
    metavar: str = ""
    goes: str = ""  # where the value goes: a dotted path into the command's config, or a sentence
    default_text: str = ""  # what --help and the docs say when the default is None or derived
    commands: tuple[str, ...] = ()  # who reads it; default: the command its table is named after
    check: Callable[[Any], Any] | None = None  # a further check; raises ValueError saying why

    @property
    def name(self) -> str:
        return f"{self.section}.{self.key}"

    @property
    def option(self) -> str:
        return self.flag or "--" + self.key.replace("_", "-")

    @property
    def used_by(self) -> tuple[str, ...]:
        return self.commands or (self.section,)

    def allowed(self) -> str:
        """The values it takes, in words: ``>= 0 s``, ``[0, 10] m``, ``one of route, here``."""
        unit = f" {self.unit}" if self.unit else ""
        if self.choices:
            return "one of " + ", ".join(self.choices)
        if self.kind is bool:
            return "true or false"
        if self.kind is str:
            return self.takes or ("a file path" if self.path else "text")
        what = "an integer" if self.kind is int else "a number"
        lo = None if self.low is None else f"{self.low:g}"
        hi = None if self.high is None else f"{self.high:g}"
        if lo is not None and hi is not None:
            return f"{what} in {'(' if self.low_open else '['}{lo}, {hi}]{unit}"
        if lo is not None:
            return f"{what} {'>' if self.low_open else '>='} {lo}{unit}"
        return f"{what}{unit}"

    def shown_default(self) -> str:
        if self.default_text:
            return self.default_text
        if self.default is REQUIRED:
            return "required"
        if self.default is None:
            return "off"
        if self.kind is bool:
            return "on" if self.default else "off"
        return f"{self.default:g} {self.unit}".strip() if self.kind is float else str(self.default)

    def checked(self, value: Any) -> Any:
        """``value`` as this setting takes it, else ValueError: what is wrong and what is allowed (one line)."""
        allowed = self.allowed()
        if self.kind is bool:
            if not isinstance(value, bool):
                raise ValueError("is not true or false")
            return value
        if self.kind is str:
            if not isinstance(value, str) or not value:
                raise ValueError(f"is not {allowed}")
            if self.choices and value not in self.choices:
                raise ValueError(f"is not {allowed}")
        else:
            number = isinstance(value, int | float) and not isinstance(value, bool)
            if not number or (self.kind is int and not isinstance(value, int)):
                raise ValueError(f"is not {allowed}")
            if not math.isfinite(value):
                raise ValueError(f"is not finite (allowed: {allowed})")
            too_low = self.low is not None and (value <= self.low if self.low_open else value < self.low)
            if too_low or (self.high is not None and value > self.high):
                raise ValueError(f"is out of range (allowed: {allowed})")
            value = self.kind(value)
        if self.check is not None:
            try:
                self.check(value)
            except ValueError as exc:
                raise ValueError(f"is refused: {exc}") from None
        return value
