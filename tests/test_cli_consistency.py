"""Every console script: help with examples, the prog the user typed, one spelling per concept, old spellings gone."""

from __future__ import annotations

import argparse
import sys
import types
from pathlib import Path

import pytest

from pectoral_gym.tools import cli_reference
from pectoral_gym.tools.cli_common import COMMANDS, MODULE_COMMANDS, prog_name
from pectoral_gym.tools.cli_reference import iter_parsers, reference_markdown

ROOT = Path(__file__).resolve().parents[1]
ALL_COMMANDS = {**COMMANDS, **MODULE_COMMANDS}

# Old spellings no parser may show in its help (all gone: see REMOVED).
RETIRED = {"--log-dir", "--n-timesteps", "--quiet", "--baseline", "--envs", "--controllers", "--train-env",
           "--storage-path", "--output", "-o", "--no-plot", "--max-steps"}

# Spellings deprecated in 0.2.0 and gone since: (command, arguments every parse needs, the old spelling's
# arguments). Not here: pectoral-scaling calibrate's --no-plot, which argparse takes as an abbreviation of
# --no-plots, as it takes any unambiguous prefix of an option.
REMOVED = [
    ("pectoral-fish", [], ["demo", "--out", "x"]),
    ("pectoral-fish", [], ["bench", "--quick"]),
    ("pectoral-scaling", ["identify"], ["--quiet"]),
    ("pectoral-train", [], ["--n-timesteps", "1e4"]),
    ("pectoral-train", [], ["--log-dir", "d"]),
    ("pectoral-evaluate", ["--policy", "run"], ["--baseline", "hand"]),
    ("pectoral-benchmark", [], ["--controllers", "hand", "nmpc"]),
    ("pectoral-benchmark", [], ["--envs", "full", "robot"]),
    ("pectoral-benchmark", [], ["--version", "v0"]),
    ("pectoral-sweep", [], ["--n-timesteps", "1e5"]),
    ("pectoral-sweep", [], ["--storage-path", "d"]),
    ("pectoral-seeds", [], ["--train-env", "PectoralFish-Full-v1"]),
    ("python -m pectoral_gym.agents.nmpc.compare", ["--variants", "{}"], ["--max-steps", "9"]),
    ("python -m pectoral_gym.agents.controllers.band_study", [], ["--quiet"]),
    ("pectoral-deploy", [], ["--max-steps", "5"]),
    ("pectoral-deploy", [], ["--quiet"]),
    ("pectoral-camera-calibrate", ["--from-emulator"], ["--output", "c.json"]),
    ("pectoral-camera-calibrate", ["--from-emulator"], ["-o", "c.json"]),
]
# Console-script names deprecated in 0.2.0 and gone since.
REMOVED_SCRIPTS = {"pectoral-calibrate"}


def _all_parsers():
    for name, command in ALL_COMMANDS.items():
        for parser in iter_parsers(command.build_parser()):
            yield name, parser


@pytest.fixture(scope="module")
def parsers() -> dict[str, argparse.ArgumentParser]:
    return {name: command.build_parser() for name, command in ALL_COMMANDS.items()}


def test_the_registry_is_the_console_scripts_of_pyproject():
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    expected = {name: command.entry_point for name, command in COMMANDS.items()}
    assert scripts == expected
    assert not REMOVED_SCRIPTS & set(scripts)


@pytest.mark.parametrize("name", sorted(ALL_COMMANDS))
def test_help_exits_0_with_the_prog_typed_and_examples(name, parsers, capsys):
    for parser in iter_parsers(parsers[name]):
        with pytest.raises(SystemExit) as done:
            parser.parse_args(["--help"])
        assert done.value.code == 0
        out = capsys.readouterr().out
        assert out.startswith(f"usage: {parser.prog}") and parser.prog.startswith(name), out[:200]
        assert parser.description, f"{parser.prog}: no description"
        assert "examples:\n  " in (parser.epilog or ""), f"{parser.prog}: no examples in its epilog"


def test_no_parser_shows_a_retired_spelling():
    for _name, parser in _all_parsers():
        shown = {option for action in parser._actions if action.help != argparse.SUPPRESS
                 for option in action.option_strings}
        assert not shown & RETIRED, f"{parser.prog} shows {sorted(shown & RETIRED)}"


@pytest.mark.parametrize("name", sorted(ALL_COMMANDS))
def test_bad_arguments_exit_2_with_a_one_line_reason(name, parsers, capsys):
    with pytest.raises(SystemExit) as done:
        parsers[name].parse_args(["--no-such-option"])
    assert done.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"{name}: error: "), err


@pytest.mark.parametrize(("name", "base", "old"), REMOVED, ids=lambda v: " ".join(v) if isinstance(v, list) else v)
def test_a_removed_spelling_is_a_usage_error(name, base, old, parsers, capsys):
    with pytest.raises(SystemExit) as done:
        parsers[name].parse_args([*base, *old])
    assert done.value.code == 2
    assert old[0] in capsys.readouterr().err


def test_prog_is_what_the_user_typed(monkeypatch):
    as_module = types.ModuleType("__main__")
    as_module.__spec__ = types.SimpleNamespace(name="pectoral_gym.__main__")
    monkeypatch.setitem(sys.modules, "__main__", as_module)
    assert prog_name("pectoral-fish", "pectoral_gym", "pectoral_gym.tools.cli") == "python -m pectoral_gym"
    assert prog_name("pectoral-train", "pectoral_gym.agents.training.train") == "pectoral-train"  # another -m

    as_script = types.ModuleType("__main__")
    as_script.__spec__ = None  # a console script's wrapper
    monkeypatch.setitem(sys.modules, "__main__", as_script)
    monkeypatch.setattr(sys, "argv", ["/venv/bin/pectoral-calibrate", "--help"])  # a stale wrapper of the old name
    calibrate = "pectoral-camera-calibrate"
    assert prog_name(calibrate, "pectoral_gym.hardware.vision.calibrate") == calibrate
    monkeypatch.setattr(sys, "argv", ["/venv/bin/pytest"])
    assert prog_name("pectoral-train", "pectoral_gym.agents.training.train") == "pectoral-train"
    monkeypatch.setattr(sys, "argv", ["/venv/bin/pectoral-demo"])  # the demo runs the deploy in its process
    assert prog_name("pectoral-deploy", "pectoral_gym.hardware.deploy") == "pectoral-deploy"
    assert prog_name(None, "pectoral_gym.agents.nmpc.compare") == "python -m pectoral_gym.agents.nmpc.compare"


def test_every_command_module_has_build_parser_and_main():
    import importlib

    for command in ALL_COMMANDS.values():
        module = importlib.import_module(command.module)
        assert callable(module.build_parser) and callable(module.main), command.module


def test_the_cli_reference_is_current():
    committed = (ROOT / "docs" / "reference" / "cli.md").read_text()
    assert reference_markdown() == committed, (
        "docs/reference/cli.md is stale: run python -m pectoral_gym.tools.cli_reference --markdown and commit it")


def test_the_reference_writer_command(tmp_path, capsys):
    assert cli_reference.main(["--markdown", str(tmp_path / "cli.md")]) == 0
    assert (tmp_path / "cli.md").read_text() == reference_markdown()


def test_an_unknown_subcommand_error_lists_only_the_current_names(parsers, capsys):
    with pytest.raises(SystemExit) as done:
        parsers["pectoral-fish"].parse_args(["frobnicate"])
    assert done.value.code == 2
    err = capsys.readouterr().err
    assert "'patterns'" in err and "'step-rate'" in err and "'demo'" not in err and "'bench'" not in err
