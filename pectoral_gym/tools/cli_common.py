"""What every pectoral-gym command line shares: its ``prog``, its help layout, deprecated spellings, the registry.

- :func:`prog_name`: the program name that matches what the user typed (``pectoral-train``, or
  ``python -m pectoral_gym.agents.training.train`` when run with ``-m``).
- :class:`HelpFormatter`: descriptions and example epilogs kept as written, defaults shown.
- :func:`deprecated_alias` and :func:`subcommands`: an old flag or subcommand name that still works for one
  release, hidden from ``--help``, with one line on stderr saying what replaces it.
- :data:`COMMANDS`: every console script, its module and parser, so tests and the docs reach every parser
  without running a tool.

``python -m pectoral_gym.tools.cli_reference --markdown [FILE]`` writes the command-line reference
(``docs/reference/cli.md``) from the parsers themselves (:mod:`pectoral_gym.tools.cli_reference`).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import textwrap
from collections.abc import Callable, Sequence
from dataclasses import dataclass

__all__ = ["COMMANDS", "DEPRECATED_SCRIPTS", "MODULE_COMMANDS", "REMOVED_IN", "Command", "DeprecatedAlias",
           "HelpFormatter", "deprecated_alias", "examples", "prog_name", "subcommands", "warn_deprecated"]

REMOVED_IN = "0.3.0"  # the release in which the deprecated spellings go


def prog_name(script: str | None, *modules: str) -> str:
    """The ``prog`` of a parser: what the user typed to run it.

    Args:
        script: The console script (``pectoral-train``); None for a module that has none.
        *modules: The modules that run this command with ``python -m`` (a package's name runs its
            ``__main__``).

    Returns:
        ``python -m <module>`` when ``__main__`` is one of ``modules`` (or there is no console script), else
        ``script``, or the deprecated name of it the user typed (:data:`DEPRECATED_SCRIPTS`). Another program
        that calls this command's ``main`` (``pectoral-demo`` runs ``pectoral-deploy``) does not lend it its name.
    """
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    running = spec.name.removesuffix(".__main__") if spec is not None else None
    if running is not None and running in modules:
        return f"python -m {running}"
    if script is None:
        return f"python -m {modules[0]}"
    typed = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    old_names = {old for old, (new, _) in DEPRECATED_SCRIPTS.items() if new == script}
    return typed if typed in old_names and running is None else script  # else: not this command's own script


def warn_deprecated(prog: str, old: str, new: str) -> None:
    """Print the one-line deprecation notice of ``old`` (a flag, subcommand or script name) to stderr."""
    print(f"{prog}: {old} is deprecated, use {new} (the old spelling goes in {REMOVED_IN})", file=sys.stderr)


class HelpFormatter(argparse.HelpFormatter):
    """Prose wrapped, example blocks kept as written, each option's default shown unless its help says it.

    In a description or epilog, a paragraph (lines between blank lines) with an indented line is kept as written
    (``examples:`` and its command lines); the others are wrapped to the terminal. A default of None, False or an
    empty list, or a flag's, is not shown (it means "not given"); a help text that already names its default
    (``default``, ``%(default)s``) is left as it is.
    """

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        paragraphs = text.strip("\n").split("\n\n")
        return "\n\n".join(
            "\n".join(indent + line for line in block.splitlines())
            if any(line.startswith(" ") for line in block.splitlines())
            else textwrap.fill(" ".join(block.split()), width, initial_indent=indent, subsequent_indent=indent)
            for block in paragraphs)

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        unset = (default is None or default is False or default is argparse.SUPPRESS or default == []
                 or action.nargs == 0)  # a flag: its default is "not given"
        if unset or "default" in text.lower() or not action.option_strings or action.help == argparse.SUPPRESS:
            return action.help
        return f"{text} (default: %(default)s)" if text else "(default: %(default)s)"


def examples(*lines: str, note: str = "") -> str:
    """An epilog: ``examples:`` and the command lines indented, then ``note`` (for :class:`HelpFormatter`)."""
    text = "examples:\n" + "\n".join(f"  {line}" for line in lines)
    return f"{text}\n\n{note}" if note else text


class DeprecatedAlias(argparse.Action):
    """An old spelling of an option: parses as the canonical option, says once on stderr what replaces it.

    Made by :func:`deprecated_alias`; hidden from ``--help`` and from the usage line.
    """

    def __init__(self, option_strings: Sequence[str], dest: str, canonical: argparse.Action, **kwargs) -> None:
        super().__init__(option_strings, dest=canonical.dest, nargs=canonical.nargs, const=canonical.const,
                         default=argparse.SUPPRESS, type=canonical.type, choices=canonical.choices,
                         help=argparse.SUPPRESS, metavar=canonical.metavar)
        self.canonical = canonical

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values,
                 option_string: str | None = None) -> None:
        """Say what replaces the old spelling, then act as the canonical option."""
        new = self.canonical.option_strings[-1] if self.canonical.option_strings else self.canonical.dest
        warn_deprecated(parser.prog, option_string or self.option_strings[0], new)
        self.canonical(parser, namespace, values, new)


def deprecated_alias(container, old: str, canonical: argparse.Action) -> argparse.Action:
    """Declare ``old`` (e.g. ``--n-timesteps``) an alias of the option ``canonical`` for one release.

    Args:
        container: The parser, argument group or mutually exclusive group ``canonical`` belongs to (an alias of
            a member of a required group must be in that group to satisfy it).
        old: The old option string.
        canonical: The action ``add_argument`` returned for the canonical spelling.

    Returns:
        The alias's action (a :class:`DeprecatedAlias`).
    """
    return container.add_argument(old, action=DeprecatedAlias, canonical=canonical)


class _Choices(dict):
    """Subcommand name -> parser; iterating skips the deprecated names (so no message lists them), ``in`` does not."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.hidden: set[str] = set()

    def __iter__(self):
        return (name for name in super().__iter__() if name not in self.hidden)


class _Subcommands(argparse._SubParsersAction):  # argparse's only way to dispatch subcommands
    """Subparsers that also accept deprecated names (hidden, with a notice); ``dest`` gets the new name."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._name_parser_map = self.choices = _Choices(self._name_parser_map)
        self.deprecated: dict[str, str] = {}

    def add_deprecated(self, old: str, new: str) -> None:
        """Let ``old`` run the subcommand ``new`` for one release; neither ``--help`` nor an error lists it."""
        self.choices[old] = self.choices[new]
        self.choices.hidden.add(old)
        self.deprecated[old] = new

    def add_parser(self, name: str, **kwargs) -> argparse.ArgumentParser:
        """``add_parser`` with :class:`HelpFormatter` as the default formatter."""
        kwargs.setdefault("formatter_class", HelpFormatter)
        return super().add_parser(name, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        if values and values[0] in self.deprecated:
            warn_deprecated(parser.prog, values[0], self.deprecated[values[0]])
            values = [self.deprecated[values[0]], *values[1:]]
        super().__call__(parser, namespace, values, option_string)


def subcommands(parser: argparse.ArgumentParser, **kwargs) -> _Subcommands:
    """``parser.add_subparsers(**kwargs)`` whose result also has ``add_deprecated(old, new)``.

    Subcommand parsers default to :class:`HelpFormatter`.
    """
    return parser.add_subparsers(action=_Subcommands, **kwargs)


@dataclass(frozen=True)
class Command:
    """A console script: its name, the module that defines it and the module's parser factory."""

    name: str
    module: str
    parser: str = "build_parser"
    entry: str = "main"

    def build_parser(self) -> argparse.ArgumentParser:
        """The command's argument parser (imports its module)."""
        factory: Callable[[], argparse.ArgumentParser] = getattr(importlib.import_module(self.module), self.parser)
        return factory()

    @property
    def entry_point(self) -> str:
        """The ``[project.scripts]`` value: ``module:main``."""
        return f"{self.module}:{self.entry}"


COMMANDS: dict[str, Command] = {c.name: c for c in (
    Command("pectoral-fish", "pectoral_gym.tools.cli"),
    Command("pectoral-scaling", "pectoral_gym.scaling.cli"),
    Command("pectoral-train", "pectoral_gym.agents.training.train"),
    Command("pectoral-evaluate", "pectoral_gym.agents.training.evaluate"),
    Command("pectoral-demo", "pectoral_gym.agents.training.demo"),
    Command("pectoral-benchmark", "pectoral_gym.agents.studies.benchmark"),
    Command("pectoral-sweep", "pectoral_gym.agents.studies.sweep"),
    Command("pectoral-seeds", "pectoral_gym.agents.studies.seeds"),
    Command("pectoral-emulator", "pectoral_gym.hardware.emulator"),
    Command("pectoral-deploy", "pectoral_gym.hardware.deploy"),
    Command("pectoral-firmware-check", "pectoral_gym.hardware.firmware_check"),
    Command("pectoral-camera-calibrate", "pectoral_gym.hardware.vision.calibrate"),
)}
"""Every console script of the distribution (``[project.scripts]``), by name."""

DEPRECATED_SCRIPTS: dict[str, tuple[str, str]] = {
    "pectoral-calibrate": ("pectoral-camera-calibrate", "pectoral_gym.hardware.vision.calibrate:deprecated_main"),
}
"""Old console-script names kept for one release: old name -> (new name, entry point of a wrapper that warns)."""

# The modules with a command line of their own that are no console script (research and benchmark tools).
MODULE_COMMANDS: dict[str, Command] = {c.name: c for c in (
    Command("python -m pectoral_gym.scaling.validation.validate", "pectoral_gym.scaling.validation.validate"),
    Command("python -m pectoral_gym.scaling.calibration.benchmark", "pectoral_gym.scaling.calibration.benchmark"),
    Command("python -m pectoral_gym.agents.nmpc.compare", "pectoral_gym.agents.nmpc.compare"),
    Command("python -m pectoral_gym.agents.controllers.band_study", "pectoral_gym.agents.controllers.band_study"),
    Command("python -m pectoral_gym.agents.studies.stack_gap", "pectoral_gym.agents.studies.stack_gap"),
    Command("python -m pectoral_gym.agents.studies.open_loop_gap", "pectoral_gym.agents.studies.open_loop_gap"),
    Command("python -m pectoral_gym.tools.layout", "pectoral_gym.tools.layout"),
)}

