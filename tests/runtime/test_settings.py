"""The settings schema (runtime/settings.py): the flags, the config file and docs/SETTINGS.md come from it,
bad values are one line naming the key, the value and what is allowed (exit 2), and every value reaches the
config the schema says it goes to."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import pytest
from runtime_fakes import FakeSim, build_velocitynet_onnx, corridor_route

from vtr.cli import main
from vtr.runtime.controller import ControllerConfig
from vtr.runtime.daemon import add_arguments, config_from_settings
from vtr.runtime.setting_spec import REQUIRED
from vtr.runtime.settings import BY_NAME, SETTINGS, for_command
from vtr.runtime.settings_cli import markdown, read_file, resolve

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "robot.toml"
COMMON = ["--sim", "tcp://127.0.0.1:5555", "--model", "m.onnx", "--route", "r.npz"]


def _parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return parser.parse_args(list(argv))


def _toml(tmp_path: Path, text: str) -> str:
    path = tmp_path / "robot.toml"
    path.write_text(text)
    return str(path)


def _usage_error(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    """The one line `vtr` prints for ``argv``, which must exit with code 2."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's usage error
        code = int(exc.code or 0)
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_docs_settings_md_is_what_the_schema_generates() -> None:
    text = (ROOT / "docs" / "SETTINGS.md").read_text()
    assert text == markdown(), "regenerate: python -m vtr.runtime.settings_cli > docs/SETTINGS.md"
    for s in SETTINGS:
        assert f"| `{s.key}` | {'(file only)' if s.file_only else f'`{s.option}`'} |" in text


def test_repeat_help_has_at_most_16_options_with_defaults_and_units(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit):
        main(["repeat", "--help"])
    text = capsys.readouterr().out
    options = set(re.findall(r"^  (--[\w-]+)", text, re.M)) - {"--config", "--help"}
    assert len(options) <= 16 and options == {s.option for s in for_command("repeat") if not s.file_only}
    flat = " ".join(text.split())
    assert "(default: 10 s; a number >= 0 s)" in flat and "(default: 0.25 m; a number in [0, 10] m)" in flat
    for removed in (
        "--e-m",
        "--thresholds",
        "--stall-steps",
        "--settle",
        "--zero-bias",
        "--paper",
        "--match",
    ):
        assert removed + " " not in text and removed + "\n" not in text


def test_each_default_passes_its_own_check_and_help_is_one_line() -> None:
    for s in SETTINGS:
        if s.default not in (REQUIRED, None):
            assert s.checked(s.default) == s.default, s.name
        assert "\n" not in s.help and s.goes, s.name


def test_the_example_file_loads_for_every_command() -> None:
    tables = read_file(EXAMPLE)
    assert Path(tables["repeat"]["model"]) == EXAMPLE.parent / "../models/velocitynet.onnx"
    assert Path(tables["repeat"]["model"]).is_file()  # relative to the file, from any directory
    run = config_from_settings(resolve(_parse("--config", str(EXAMPLE), "--route", "r.npz"), "repeat"))
    assert run.sim == "tcp://127.0.0.1:5555" and run.repeat.controller == ControllerConfig()
    for command in ("teach", "check-robot"):
        parser = argparse.ArgumentParser()
        from vtr.runtime.settings_cli import add_arguments as add_settings

        add_settings(parser, command)
        assert resolve(parser.parse_args(["--config", str(EXAMPLE)]), command)["robot.address"] == run.sim


def test_flags_override_the_file_which_overrides_the_defaults(tmp_path: Path) -> None:
    path = _toml(
        tmp_path, '[robot]\naddress = "tcp://10.0.0.2:5555"\n[repeat]\nwait = 3\nmodel = "/m.onnx"\n'
    )
    got = resolve(_parse("--config", path, "--route", "r.npz", "--wait", "4.5"), "repeat")
    assert got["repeat.wait"] == 4.5 and got.where["repeat.wait"] == "--wait"
    assert got["robot.address"] == "tcp://10.0.0.2:5555" and got.where["robot.address"].startswith(path)
    assert got["repeat.model"] == "/m.onnx" and got["repeat.threads"] == BY_NAME["repeat.threads"].default
    assert isinstance(got["repeat.wait"], float)
    assert (
        resolve(_parse("--config", path, "--route", "r"), "repeat")["repeat.wait"] == 3.0
    )  # an int is a number


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("[repeat]\nwiat = 3\n", ["robot.toml", "unknown key repeat.wiat", "did you mean wait?"]),
        ("[repeat]\nwait = -1\n", ["robot.toml", "repeat.wait = -1", "out of range", ">= 0 s"]),
        ('[repeat]\nwait = "ten"\n', ['repeat.wait = "ten"', "is not a number >= 0 s"]),
        ("[repeat]\nthreads = 1.5\n", ["repeat.threads = 1.5", "an integer >= 1"]),
        ('[repeat]\nstart = "middle"\n', ['repeat.start = "middle"', "one of route, here, anywhere"]),
        ("[robot]\nradius = 6\n", ["robot.radius = 6", "(0, 5] m"]),
        ('[robot]\naddress = "http://x:1"\n', ['robot.address = "http://x:1"', "http://"]),
        ("[repeat]\njson = 1\n", ["repeat.json = 1", "true or false"]),
        ("[repeat]\nwait = nan\n", ["repeat.wait = NaN", "not finite"]),
        ("[repet]\nwait = 1\n", ["unknown table [repet]", "did you mean [repeat]?"]),
        ("wait = 1\n", ["wait = 1 is outside a table", "[repeat]"]),
        ("[teach]\nwait = 1\n", ["unknown key teach.wait", "wait goes in [repeat]"]),
        ("[repeat]\nwait = \n", ["robot.toml: not a TOML file"]),
        (
            "[repeat]\nstop_distance = 0.7\n",
            ["stop_distance 0.7 m (", "robot.toml", "slowdown_distance 0.6 m"],
        ),
    ],
)
def test_a_bad_file_is_one_line_naming_file_key_value_and_range(
    text: str, words: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    line = _usage_error(capsys, ["repeat", *COMMON, "--config", _toml(tmp_path, text)])
    for word in words:
        assert word in line, line


def test_a_bad_file_stops_teach_and_check_robot_too(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _toml(tmp_path, "[repeat]\nwait = -1\n")
    assert "repeat.wait = -1" in _usage_error(capsys, ["check-robot", "--config", path])
    assert "repeat.wait = -1" in _usage_error(
        capsys, ["teach", "--config", path, "--route", "r.json", "--out", str(tmp_path / "o.npz")]
    )
    assert "cannot read" in _usage_error(capsys, ["check-robot", "--config", str(tmp_path / "none.toml")])


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--wait", "-1"], ["--wait", "-1 is out of range", "a number >= 0 s"]),
        (["--wait", "soon"], ["--wait", "'soon' is not a number >= 0 s"]),
        (["--speed", "1.5"], ["--speed", "1.5 is out of range", "a number in (0, 1] x"]),
        (["--foxglove", "70000"], ["--foxglove", "[0, 65535]"]),
        (["--profile", "fast"], ["--profile", "fast is not one of default, paper"]),
        (
            ["--stop-distance", "0.7"],
            ["stop_distance 0.7 m (--stop-distance)", "slowdown_distance 0.6 m (default)"],
        ),
        (["--robot-radius", "0"], ["--robot-radius", "(0, 5] m"]),
    ],
)
def test_a_bad_flag_is_one_line_naming_flag_value_and_range(
    argv: list[str], words: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    line = _usage_error(capsys, ["repeat", *COMMON, *argv])
    for word in words:
        assert word in line, line


def test_a_missing_required_setting_names_the_flag_and_the_key(capsys: pytest.CaptureFixture[str]) -> None:
    line = _usage_error(capsys, ["repeat", "--sim", "tcp://127.0.0.1:5555", "--route", "r.npz"])
    assert "needs --model (or model in the config file's [repeat])" in line


def test_a_file_only_setting_has_no_flag_but_the_file_sets_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert BY_NAME["repeat.threads"].file_only
    with pytest.raises(SystemExit):
        _parse(*COMMON, "--threads", "2")
    assert "unrecognized arguments: --threads" in capsys.readouterr().err
    path = _toml(tmp_path, "[repeat]\nthreads = 2\n")
    assert resolve(_parse(*COMMON, "--config", path), "repeat")["repeat.threads"] == 2
    assert "| `threads` | (file only) |" in markdown()


def test_schema_ranges_are_the_configs_own(tmp_path: Path) -> None:
    """The schema's bounds neither refuse what the configs take nor let through what they refuse."""
    base = resolve(_parse(*COMMON), "repeat").values
    for name, good, bad in (
        ("robot.radius", 5.0, 5.01),
        ("repeat.slowdown_distance", 10.0, 10.01),
        ("repeat.wait", 0.0, -0.01),
        ("repeat.threads", 1, 0),
        ("repeat.timeout", 1e-3, 0.0),
        ("repeat.speed", 1.0, 1.01),
    ):
        config_from_settings({**base, name: BY_NAME[name].checked(good)})
        with pytest.raises(ValueError):
            BY_NAME[name].checked(bad)
        with pytest.raises(ValueError):
            config_from_settings({**base, name: bad})


def test_every_value_goes_where_the_schema_says() -> None:
    base = resolve(_parse(*COMMON), "repeat").values
    changed = {"robot.radius": 0.2, "repeat.wait": 2.5, "repeat.stop_distance": 0.1, "repeat.log": "x.jsonl"}
    changed |= {
        "repeat.slowdown_distance": 0.3,
        "repeat.threads": 2,
        "repeat.timeout": 0.5,
        "repeat.foxglove": 0,
        "repeat.speed": 0.5,
    }
    changed |= {"repeat.mcap": "x.mcap", "repeat.model": "n.onnx", "repeat.route": "q.npz"}
    changed |= {"repeat.motion": "continuous", "robot.address": "tcp://10.1.1.1:7"}
    run = config_from_settings({**base, **changed})
    for s in for_command("repeat"):
        path = s.goes.removeprefix("RepeatRunConfig.")
        if s.name in changed and re.fullmatch(r"[\w.]+", path):
            value = run
            for part in path.split("."):
                value = getattr(value, part)
            assert value == changed[s.name], s.name
    assert {s.name for s in for_command("repeat") if re.fullmatch(r"RepeatRunConfig[\w.]+", s.goes)} <= set(
        changed
    )


def test_a_repeat_from_a_config_file_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from vtr.sim2d.server import ServerThread

    build_velocitynet_onnx(str(tmp_path / "tiny.onnx"))
    corridor_route().save(tmp_path / "route.npz")
    with ServerThread(FakeSim()) as server:
        # the fake policy steers on brightness: raw error, no light matching (the paper's profile)
        text = f'[robot]\naddress = "{server.endpoint}"\n[repeat]\nmodel = "tiny.onnx"\nprofile = "paper"\n'
        argv = ["repeat", "--config", _toml(tmp_path, text), "--route", str(tmp_path / "route.npz"), "--json"]
        assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["completed"] and summary["subgoals_reached"] == summary["subgoals_total"]


def test_teach_takes_the_address_timeout_and_retries_from_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    script = tmp_path / "r.json"
    script.write_text(
        '{"start": {"x": 0, "y": 0, "yaw": 0}, "segments": [{"v": 0.1, "w": 0, "duration": 1}]}'
    )
    text = '[robot]\naddress = "tcp://127.0.0.1:9"\n[teach]\ntimeout = 0.05\nretries = 1\n'  # nobody there
    argv = [
        "teach",
        "--config",
        _toml(tmp_path, text),
        "--route",
        str(script),
        "--out",
        str(tmp_path / "o.npz"),
    ]
    assert "no reply from tcp://127.0.0.1:9" in _usage_error(capsys, argv)
