"""No lab notebook in the product: issue numbers, commit hashes, lab dates and load averages stay out of the code,
the command-line help, the docstrings and the user docs.

A user has no issue tracker to look "issue 27" up in, no checkout of the commit a figure names, and no use for the
day it was measured: the text says what a rule or a figure means and which command reproduces it. History belongs
in ``CHANGELOG.md`` (by version) and in the dated research notes of ``docs/notes/``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: What is scanned: source, docs and configuration (each path relative to the checkout).
SUFFIXES = {".py", ".md", ".yml", ".yaml"}
#: Folders never scanned: the dated research notes, and what is not the project's own text.
SKIPPED_DIRS = {"docs/notes", "site", "build", "dist", "node_modules", "__pycache__"}
#: Files that may carry history: the changelog names versions and dates; the dated studies of docs/validation are
#: research notes kept beside their scripts (``docs/notes/index.md`` says so); this file holds the scanner's examples.
SKIPPED_FILES = {"CHANGELOG.md", "docs/changelog.md", "docs/validation/fidelity/README.md",
                 "docs/validation/speed/README.md", "docs/validation/step_path/README.md",
                 "tests/test_no_lab_notebook.py"}
ISSUE = re.compile(r"\bissues?\s+#?\d+", re.IGNORECASE)
DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b")
#: A research note's file name is a link, not a lab date.
NOTE_NAME = re.compile(r"notes/20\d\d-\d\d-\d\d-[\w.-]+\.md")
_HEX = r"[0-9a-f]{7,40}"
#: A commit: 7-40 lower-case hex characters (as git prints them), in backticks or after a word that names a revision.
COMMIT = re.compile(rf"`({_HEX})`|\b(?i:commits?|main|checkout of|worktree of|code of|tag|against|at)\s+\(?({_HEX})\b")
LOAD = re.compile(r"\bload\s+average", re.IGNORECASE)


def _is_hash(token: str) -> bool:
    """A hex word with both digits and letters (a bare number or word is not a hash)."""
    return any(c.isdigit() for c in token) and any(c.isalpha() for c in token)


def notebook_matches(text: str) -> list[tuple[int, str]]:
    """Every issue number, commit hash, ISO date and load average in ``text``: ``(offset, matched string)``."""
    undated = NOTE_NAME.sub(lambda m: "x" * len(m.group(0)), text)  # same offsets, no note names
    found = [(m.start(), m.group(0)) for m in ISSUE.finditer(text)]
    found += [(m.start(), m.group(0)) for m in DATE.finditer(undated)]
    found += [(m.start(), m.group(0)) for m in COMMIT.finditer(text) if _is_hash(m.group(1) or m.group(2))]
    found += [(m.start(), m.group(0)) for m in LOAD.finditer(text)]
    return sorted(found)


def notebook_entries(text: str) -> list[str]:
    """The matched strings of :func:`notebook_matches`, in the order they occur."""
    return [hit for _, hit in notebook_matches(text)]


def scanned_files() -> list[Path]:
    """The project's own text files (hidden folders, such as ``.venv`` and ``.git``, not entered)."""
    files = []
    for folder, dirs, names in os.walk(ROOT):
        rel_folder = Path(folder).relative_to(ROOT)
        dirs[:] = [d for d in dirs if not d.startswith(".") and not d.endswith(".egg-info")
                   and d not in SKIPPED_DIRS and (rel_folder / d).as_posix() not in SKIPPED_DIRS]
        files += [Path(folder) / name for name in names if Path(name).suffix in SUFFIXES
                  and (rel_folder / name).as_posix() not in SKIPPED_FILES]
    return sorted(files)


@pytest.mark.parametrize("text, expected", [
    ("fit from run logs (issue 27)", ["issue 27"]),
    ("see Issues #4 and 5", ["Issues #4"]),
    ("measured 2026-12-04 late", ["2026-12-04"]),
    ("the [note](notes/2026-12-04-rate-rule.md)", []),
    ("with the code of main 9cedcb7", ["main 9cedcb7"]),
    ("a checkout of `81e1d0d`", ["`81e1d0d`"]),
    ("with the code of a94d111 and", ["code of a94d111"]),
    ("a load average of 3-5", ["load average"]),
    ("to issue\n    29's degraded one", ["issue\n    29"]),
    # not history: numbers, colours, digests, words
    ("seed 1234567, colour `#1f77b4`, 0.2.0, `decaff`, `1234567`, `deadbeef`", []),
    ("the broadcast address `000000000000FFFF`, at 100 Hz", []),
    ("CleanRL's [issue tracker](https://github.com/vwxyzjn/cleanrl/issues/499)", []),
])
def test_the_scanner_finds_history_and_only_history(text: str, expected: list[str]) -> None:
    assert notebook_entries(text) == expected


def test_no_lab_notebook_in_code_and_docs() -> None:
    offenders = []
    for path in scanned_files():
        rel = path.relative_to(ROOT).as_posix()
        text = path.read_text(encoding="utf-8")
        offenders += [f"{rel}:{text.count(chr(10), 0, offset) + 1}: {hit!r}" for offset, hit in notebook_matches(text)]
    assert not offenders, "history in code or docs (say what it means, or move it to a research note):\n" + \
        "\n".join(offenders)


def test_no_lab_notebook_in_help() -> None:
    pytest.importorskip("stable_baselines3")  # the agents' commands import it to build their parsers
    from pectoral_gym.tools.cli_reference import reference_markdown

    text = reference_markdown()
    hits = [f"{text.count(chr(10), 0, offset) + 1}: {hit!r}" for offset, hit in notebook_matches(text)]
    assert not hits, "history in the --help of a command (lines of the generated reference):\n" + "\n".join(hits)
