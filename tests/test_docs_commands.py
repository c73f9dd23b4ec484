"""Every command quoted in the README's and the Getting-started page's bash blocks parses (``--help`` level).

A command is a line (``\\`` continuations joined) of a ```` ```bash ```` block, or one part of a ``&&``/``;``/``|``
chain, that starts with a console script (``pectoral-...``, also ``.venv/bin/pectoral-...``) or
``python -m pectoral_gym...``, after any ``VAR=value`` prefixes. Its arguments go through the registered parser's
``parse_args`` (nothing runs), so a renamed or misspelt flag in the docs fails here, naming the file and command.
"""

from __future__ import annotations

import argparse
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest

from pectoral_gym.tools.cli_common import COMMANDS, MODULE_COMMANDS, Command

ROOT = Path(__file__).resolve().parents[1]
# README and every current page (the dated research notes quote commands as they were then, so they are left out)
DOCS = ("README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").rglob("*.md")
                             if "notes" not in p.relative_to(ROOT / "docs").parts[:1]
                             and "validation" not in p.relative_to(ROOT / "docs").parts[:1]))
SHELL_ASSIGNMENT = re.compile(r"^(?P<name>[A-Za-z_]\w*)=(?P<value>\"[^\"]*\"|'[^']*'|\S*)$")
INLINE_DOCS = ("README.md", "docs/getting-started.md", "docs/results.md")  # their tables quote whole commands inline
INLINE_COMMAND = re.compile(r"(?<!`)`((?:\.venv/bin/)?(?:pectoral-[a-z-]+|python -m pectoral_gym[\w.]*) [^`]*)`(?!`)")
SHELL_BLOCK = re.compile(r"^```(?:bash|sh|shell|console)[ \t]*\n(.*?)^```", re.S | re.M)
OPERATORS = {"&&", "||", ";", "|", "&"}
ENV_ASSIGNMENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*=")
PYTHON = re.compile(r"^(?:.*/)?python(?:3(?:\.\d+)?)?$")
# python -m <module> -> its command: a console script's modules and the packages whose __main__ runs one
MODULES: dict[str, Command] = {command.module: command for command in (*COMMANDS.values(), *MODULE_COMMANDS.values())}
MODULES.update({"pectoral_gym": COMMANDS["pectoral-fish"], "pectoral_gym.scaling": COMMANDS["pectoral-scaling"]})


@dataclass(frozen=True)
class DocCommand:
    """One command quoted in a doc: where, the text as quoted, the registered command and its arguments."""

    source: str
    text: str
    command: Command | None  # None: a pectoral_gym command line no registry entry knows
    args: tuple[str, ...]


def shell_commands(markdown: str, inline: bool = False) -> list[list[str]]:
    """The simple commands (token lists) of every shell block: continuations joined, comments dropped, chains split.

    With ``inline``, also the commands written inline with their arguments (`` `pectoral-deploy --seed 1` ``, as in
    the results tables).
    """
    commands = []
    for block in SHELL_BLOCK.findall(markdown):
        variables: dict[str, str] = {}  # NAME="..." lines of the block, expanded in the lines after them
        for line in block.replace("\\\n", " ").splitlines():
            line = line.strip().removeprefix("$ ")
            if not line or line.startswith("#"):
                continue
            if assignment := SHELL_ASSIGNMENT.match(line):
                variables[assignment["name"]] = shlex.split(assignment["value"])[0] if assignment["value"] else ""
                continue
            line = re.sub(r"\$\{?(\w+)\}?", lambda m, known=variables: known.get(m[1], m[0]), line)
            lexer = shlex.shlex(line, posix=True, punctuation_chars=True)
            lexer.whitespace_split = True
            current: list[str] = []
            for token in lexer:
                if token in OPERATORS:
                    commands.append(current)
                    current = []
                else:
                    current.append(token)
            commands.append(current)
    if not inline:
        return [c for c in commands if c]
    prose = SHELL_BLOCK.sub("", re.sub(r"^```.*?^```", "", markdown, flags=re.S | re.M))
    for quoted in INLINE_COMMAND.findall(prose):  # a command written inline, e.g. in a table
        commands.extend(shell_commands(f"```bash\n{' '.join(quoted.split())}\n```\n"))
    return [c for c in commands if c]


def as_doc_command(source: str, tokens: list[str]) -> DocCommand | None:
    """The :class:`DocCommand` of ``tokens`` if it runs a pectoral-gym command line, else None."""
    while tokens and ENV_ASSIGNMENT.match(tokens[0]):
        tokens = tokens[1:]
    if not tokens:
        return None
    text = shlex.join(tokens)
    program = Path(tokens[0]).name
    if program.startswith("pectoral-"):
        return DocCommand(source, text, COMMANDS.get(program), tuple(tokens[1:]))
    if PYTHON.match(tokens[0]) and tokens[1:2] == ["-m"] and len(tokens) > 2 and (
            tokens[2] == "pectoral_gym" or tokens[2].startswith("pectoral_gym.")):
        return DocCommand(source, text, MODULES.get(tokens[2]), tuple(tokens[3:]))
    return None


def doc_commands(path: Path) -> list[DocCommand]:
    """Every pectoral-gym command quoted in the shell blocks of ``path``."""
    source = str(path.relative_to(ROOT))
    inline = source in INLINE_DOCS
    found = (as_doc_command(source, tokens) for tokens in shell_commands(path.read_text(), inline=inline))
    return [c for c in found if c is not None]


def _parser(command: Command) -> argparse.ArgumentParser:
    """``command``'s parser with no argument type that reads a file (the docs name files they make first)."""
    parser = command.build_parser()
    for action in parser._actions:
        if getattr(action.type, "__name__", "") == "fish_params":  # pectoral-deploy --emulate-params loads its file
            action.type = None
    return parser


def _existing_docs() -> list[Path]:
    return [ROOT / doc for doc in DOCS if (ROOT / doc).exists()]


def test_the_parsing_joins_lines_splits_chains_and_drops_comments():
    text = ("intro\n```bash\n# a comment\nFOO=1 .venv/bin/pectoral-train --env E \\\n    --seed 1  # trailing\n"
            "cd x && python -m pectoral_gym.scaling identify --quick; echo done\n"
            "python3 -m venv .venv && .venv/bin/python -m pytest -n 2\n```\n"
            "```python\npectoral-fish steady\n```\n")
    assert shell_commands(text) == [["FOO=1", ".venv/bin/pectoral-train", "--env", "E", "--seed", "1"],
                                    ["cd", "x"], ["python", "-m", "pectoral_gym.scaling", "identify", "--quick"],
                                    ["echo", "done"], ["python3", "-m", "venv", ".venv"],
                                    [".venv/bin/python", "-m", "pytest", "-n", "2"]]
    found = [as_doc_command("t", tokens) for tokens in shell_commands(text)]
    assert [(c.command.name, c.args) for c in found if c] == [
        ("pectoral-train", ("--env", "E", "--seed", "1")), ("pectoral-scaling", ("identify", "--quick"))]


def test_the_readme_quotes_commands():
    assert doc_commands(ROOT / "README.md"), "README.md quotes no pectoral-gym command in a ```bash block"


@pytest.mark.parametrize("doc", DOCS)
def test_every_quoted_command_parses(doc, capsys):
    path = ROOT / doc
    if not path.exists():
        pytest.skip(f"{doc} does not exist yet")
    failures = []
    for quoted in doc_commands(path):
        if quoted.command is None:
            failures.append(f"{quoted.source}: `{quoted.text}`: no such pectoral-gym command")
            continue
        try:
            _parser(quoted.command).parse_args(list(quoted.args))
        except SystemExit as stop:
            if stop.code != 0:  # 0: the command asks for --help
                reason = capsys.readouterr().err.strip().splitlines()[-1:]
                failures.append(f"{quoted.source}: `{quoted.text}` does not parse: {' '.join(reason)}")
        capsys.readouterr()
    assert not failures, "\n".join(failures)
