"""The settings of ``runtime.settings`` as flags, as a config file, and as docs/SETTINGS.md.

- :func:`add_arguments`: ``--config FILE`` and one flag per setting a command reads, grouped by the file's
  tables; ``--help`` shows each default with its unit and what is allowed. A flag not given stays unset
  (``argparse.SUPPRESS``), so the file can fill it in.
- :func:`resolve`: the defaults, overridden by the file, overridden by the flags.
- :func:`read_file`: a TOML file checked against every table, whichever command reads it (a typo in
  ``[teach]`` stops `vtr repeat` too). Relative paths in it are relative to the file.

Every value, from a flag or the file, goes through its ``Setting.checked``: a bad one is one line naming the
key (and the file), the value and what is allowed, exit 2. TOML comes from the standard library's tomllib
(Python >= 3.11), or from the tomli package on Python 3.10 (a base dependency there).

``python -m vtr.runtime.settings_cli > docs/SETTINGS.md`` writes the docs (a test checks they are current).
"""

from __future__ import annotations

import argparse
import difflib
import json
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vtr.runtime.setting_spec import REQUIRED, Setting
from vtr.runtime.settings import BY_NAME, PROFILES, SECTIONS, SETTINGS, for_command, together

#: A settings file is a few hundred bytes; anything this big is the wrong file.
MAX_FILE_BYTES = 64 * 1024


def _shown(value: Any) -> str:
    """A value as TOML writes it: strings quoted, booleans lower case."""
    try:
        return json.dumps(value)
    except (TypeError, ValueError):
        return repr(value)


def _help(s: Setting) -> str:
    allowed = "" if s.choices or s.kind in (bool, str) else f"; {s.allowed()}"
    shown = "required" if s.default is REQUIRED else f"default: {s.shown_default()}{allowed}"
    return f"{s.help} ({shown})".replace("%", "%%")


def from_text(s: Setting) -> Callable[[str], Any]:
    """The argparse ``type`` of a flag: text to a checked value, else one line saying what is allowed."""

    def convert(text: str) -> Any:
        if text is argparse.SUPPRESS:  # an optional positional not given (argparse converts its default)
            return text
        value: Any = text
        if s.kind in (int, float):
            try:
                value = s.kind(text)
            except ValueError:
                raise argparse.ArgumentTypeError(f"{text!r} is not {s.allowed()}") from None
        try:
            return s.checked(value)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"{text} {exc}") from None

    convert.__name__ = s.key
    return convert


def add_arguments(
    parser: argparse.ArgumentParser,
    command: str,
    skip: tuple[str, ...] = (),
    notes: dict[str, str] | None = None,
) -> None:
    """``--config`` and a flag for each setting ``command`` reads (but ``skip``, names like "robot.address");
    ``notes[name]`` replaces the default shown in a flag's help (e.g. "or --bag")."""
    parser.add_argument(
        "--config",
        metavar="FILE",
        default=None,
        help=f"settings file (TOML: [robot], [{command}]); flags override it (docs/SETTINGS.md)",
    )
    groups: dict[str, Any] = {}
    for s in for_command(command):
        if s.name in skip or s.file_only:
            continue
        if s.section not in groups:
            title = (
                "the robot (file: [robot])" if s.section == "robot" else f"{command} (file: [{s.section}])"
            )
            groups[s.section] = parser.add_argument_group(title)
        note = (notes or {}).get(s.name)
        text = f"{s.help} ({note})" if note else _help(s)
        kwargs: dict[str, Any] = {"dest": s.name, "default": argparse.SUPPRESS, "help": text}
        if s.kind is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        else:
            kwargs["type"] = from_text(s)
            kwargs["metavar"] = "{" + ",".join(s.choices) + "}" if s.choices else s.metavar or s.key.upper()
        groups[s.section].add_argument(s.option, **kwargs)


@dataclass(frozen=True)
class Resolved:
    """A command's settings: ``values[name]`` and where each came from (``where[name]``: a flag, a file,
    "default"). A setting nobody gave that has no default is ``REQUIRED``."""

    values: dict[str, Any]
    where: dict[str, str]

    def __getitem__(self, name: str) -> Any:
        return self.values[name]


def resolve(args: argparse.Namespace, command: str, required: bool = True) -> Resolved:
    """``command``'s settings from its defaults, ``args.config``'s file and the flags in ``args``, in that
    order; ValueError (one line) for a bad file, or a required setting nobody gave when ``required``."""
    settings = for_command(command)
    values = {s.name: s.default for s in settings}
    where = dict.fromkeys(values, "default")
    config = getattr(args, "config", None)
    if config:
        tables = read_file(config)
        for s in settings:
            if s.key in tables.get(s.section, {}):
                values[s.name], where[s.name] = tables[s.section][s.key], f"{config}: {s.name}"
    for s in settings:
        if hasattr(args, s.name):
            values[s.name], where[s.name] = getattr(args, s.name), s.option
    if required:
        for s in settings:
            if values[s.name] is REQUIRED:
                raise ValueError(f"needs {s.option} (or {s.key} in the config file's [{s.section}])")
    together(values, where)
    return Resolved(values, where)


def _load_toml(path: str) -> dict[str, Any]:
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # Python 3.10 (ROS 2 Humble boards): the same parser, the tomli package
        import tomli as tomllib
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the config file: {exc.strerror or exc}") from None
    if len(data) > MAX_FILE_BYTES:
        raise ValueError(f"{path}: over {MAX_FILE_BYTES // 1024} KiB, not a settings file")
    try:
        return tomllib.loads(data.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not a TOML file: {exc}") from None


def _unknown(path: str, section: str, key: str) -> str:
    known = [s.key for s in SETTINGS if s.section == section]
    close = difflib.get_close_matches(key, known, n=1)
    elsewhere = [s.section for s in SETTINGS if s.key == key]
    hint = f"did you mean {close[0]}? " if close else ""
    hint += f"{key} goes in [{elsewhere[0]}]; " if elsewhere else ""
    return f"{path}: unknown key {section}.{key} ({hint}[{section}] takes {', '.join(known)})"


def read_file(path: str | Path) -> dict[str, dict[str, Any]]:
    """The file's tables, every value checked (paths made relative to the file); ValueError, one line."""
    path = str(path)
    data = _load_toml(path)
    out: dict[str, dict[str, Any]] = {}
    for section, table in data.items():
        if not isinstance(table, dict):
            homes = [s.section for s in SETTINGS if s.key == section]
            where = f"put it under [{homes[0]}]" if homes else f"settings go in [{'], ['.join(SECTIONS)}]"
            raise ValueError(f"{path}: {section} = {_shown(table)} is outside a table; {where}")
        if section not in SECTIONS:
            close = difflib.get_close_matches(section, SECTIONS, n=1)
            hint = f"did you mean [{close[0]}]? " if close else ""
            raise ValueError(f"{path}: unknown table [{section}] ({hint}tables: {', '.join(SECTIONS)})")
        for key, value in table.items():
            s = BY_NAME.get(f"{section}.{key}")
            if s is None:
                raise ValueError(_unknown(path, section, key))
            try:
                value = s.checked(value)
            except ValueError as exc:
                raise ValueError(f"{path}: {s.name} = {_shown(value)} {exc}") from None
            if s.path and not Path(value).expanduser().is_absolute():
                value = str(Path(path).parent / value)
            out.setdefault(section, {})[key] = value
    return out


def markdown() -> str:
    """docs/SETTINGS.md: what the settings are, table by table."""
    lines = [
        "# Settings",
        "",
        "<!-- Generated from runtime/settings.py by `python -m vtr.runtime.settings_cli > docs/SETTINGS.md`;",
        "     tests/runtime/test_settings.py fails when this file is not what it generates. -->",
        "",
        "`vtr repeat`, `vtr teach` and `vtr check-robot` read their settings from flags and from a config file",
        "(`--config robot.toml`, TOML, one file per robot: [examples/robot.toml](../examples/robot.toml)). A flag",
        "overrides the file, the file overrides the default. Each command reads `[robot]` and its own table and",
        "checks the whole file. Relative paths in the file are relative to the file. A bad value, an unknown key",
        "or a wrong type is one line naming the key (and the file), the value and what is allowed; exit code 2.",
        "",
        "Knobs that only the evaluation's ablations vary (switch thresholds, the stall guard, settling, the",
        "progress gate, the zero bias, the taught prior, the matching method) are not settings: they are",
        "`ControllerConfig` fields, reached through `evaluation/condition_run.py`'s `CONTROLLERS`.",
        "",
        "## Profiles (`--profile`)",
        "",
        "| profile | controller | light matching | what it runs |",
        "|---|---|---|---|",
    ]
    for name, p in PROFILES.items():
        ctor = (
            "ControllerConfig()"
            if p.controller.__name__ == "ControllerConfig"
            else f"ControllerConfig.{p.controller.__name__}()"
        )
        lines.append(f"| `{name}` | `{ctor}` | {'on' if p.match_light else 'off'} | {p.help} |")
    lines += [
        "",
        "The range-scan safety layer (stop and slowdown zones, `wait`) applies under every profile.",
    ]
    for section in SECTIONS:
        rows = [s for s in SETTINGS if s.section == section]
        readers = sorted({c for s in rows for c in s.used_by}, key=SECTIONS.index)
        lines += ["", f"## [{section}]", "", f"Read by {', '.join(f'`vtr {c}`' for c in readers)}.", ""]
        lines += ["| key | flag | default | allowed | meaning | goes to |", "|---|---|---|---|---|---|"]
        for s in rows:
            flag = "(file only)" if s.file_only else f"`{s.option}`"
            cells = (f"`{s.key}`", flag, s.shown_default(), s.allowed(), s.help, s.goes)
            lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.stdout.write(markdown())
