"""What every pectoral-gym command line shares: its ``prog``, its help layout, the registry.

- :func:`prog_name`: the program name that matches what the user typed (``pectoral-train``, or
  ``python -m pectoral_gym.agents.training.train`` when run with ``-m``).
- :class:`HelpFormatter`: descriptions and example epilogs kept as written, defaults shown.
- :func:`subcommands`: subcommand parsers that use :class:`HelpFormatter`.
- :func:`add_seeds_argument`: the one spelling of ``--seeds`` (seeds and ranges ``A-B``, space-separated).
- :data:`COMMANDS`: every console script, its module and parser, so tests and the docs reach every parser
  without running a tool.

``python -m pectoral_gym.tools.cli_reference --markdown [FILE]`` writes the command-line reference
(``docs/reference/cli.md``) from the parsers themselves (:mod:`pectoral_gym.tools.cli_reference`).
"""

from __future__ import annotations

import argparse
import importlib
import sys
import textwrap
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["COMMANDS", "MODULE_COMMANDS", "Command", "HelpFormatter", "add_seeds_argument", "examples", "prog_name",
           "seed_range", "subcommands"]


def prog_name(script: str | None, *modules: str) -> str:
    """The ``prog`` of a parser: what the user typed to run it.

    Args:
        script: The console script (``pectoral-train``); None for a module that has none.
        *modules: The modules that run this command with ``python -m`` (a package's name runs its
            ``__main__``).

    Returns:
        ``python -m <module>`` when ``__main__`` is one of ``modules`` (or there is no console script), else
        ``script``. Another program that calls this command's ``main`` (``pectoral-demo`` runs
        ``pectoral-deploy``) does not lend it its name.
    """
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    running = spec.name.removesuffix(".__main__") if spec is not None else None
    if running is not None and running in modules:
        return f"python -m {running}"
    return f"python -m {modules[0]}" if script is None else script


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


def seed_range(text: str) -> list[int]:
    """``"7"`` -> ``[7]``, ``"301-335"`` -> ``[301, ..., 335]`` (both ends included): one ``--seeds`` token."""
    if "," in text:
        raise argparse.ArgumentTypeError(f"seeds are separated by spaces, not commas: {text.replace(',', ' ')!r}")
    low, sep, high = text.partition("-")
    try:
        first, last = int(low), int(high if sep else low)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a seed or a range A-B: {text!r}") from None
    if first < 0 or last < first:
        raise argparse.ArgumentTypeError(f"a range A-B needs 0 <= A <= B: {text!r}")
    return list(range(first, last + 1))


class _SeedsAction(argparse.Action):
    """Flattens the ranges of ``--seeds`` into one list, in the order given (each tool judges repeats)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        setattr(namespace, self.dest, [seed for chunk in values for seed in chunk])


def add_seeds_argument(parser: argparse.ArgumentParser, default: list[int], help: str) -> None:  # noqa: A002
    """Add ``--seeds SEED [SEED ...]``, each an integer or a range ``A-B`` (both ends included), as a flat list."""
    parser.add_argument("--seeds", type=seed_range, nargs="+", action=_SeedsAction, default=list(default),
                        metavar="SEED", help=f"{help}: seeds, or ranges A-B (both ends included)")


class _Subcommands(argparse._SubParsersAction):  # argparse's only way to dispatch subcommands
    """Subparsers whose parsers default to :class:`HelpFormatter`."""

    def add_parser(self, name: str, **kwargs) -> argparse.ArgumentParser:
        """``add_parser`` with :class:`HelpFormatter` as the default formatter."""
        kwargs.setdefault("formatter_class", HelpFormatter)
        return super().add_parser(name, **kwargs)


def subcommands(parser: argparse.ArgumentParser, **kwargs) -> _Subcommands:
    """``parser.add_subparsers(**kwargs)`` whose subcommand parsers default to :class:`HelpFormatter`."""
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

# The modules with a command line of their own that are no console script (research and benchmark tools).
MODULE_COMMANDS: dict[str, Command] = {c.name: c for c in (
    Command("python -m pectoral_gym.scaling.validation.validate", "pectoral_gym.scaling.validation.validate"),
    Command("python -m pectoral_gym.scaling.calibration.benchmark", "pectoral_gym.scaling.calibration.benchmark"),
    Command("python -m pectoral_gym.agents.nmpc.compare", "pectoral_gym.agents.nmpc.compare"),
    Command("python -m pectoral_gym.agents.controllers.band_study", "pectoral_gym.agents.controllers.band_study"),
    Command("python -m pectoral_gym.agents.studies.stack_gap", "pectoral_gym.agents.studies.stack_gap"),
    Command("python -m pectoral_gym.agents.studies.open_loop_gap", "pectoral_gym.agents.studies.open_loop_gap"),
    Command("python -m pectoral_gym.tools.layout", "pectoral_gym.tools.layout"),
    Command("python -m pectoral_gym.agents.training.hub", "pectoral_gym.agents.training.hub"),
    Command("python -m pectoral_gym.agents.training.dataset", "pectoral_gym.agents.training.dataset"),
)}

