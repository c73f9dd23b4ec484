"""Code blocks of the docs, found by a ``<!-- snippet: NAME -->`` line before them, for tests that run them."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TRAINERS_DOC = ROOT / "docs" / "guide" / "trainers.md"  # "Other trainers": one recipe per trainer


def snippet(name: str, doc: Path = TRAINERS_DOC) -> str:
    """The text of the fenced code block right after ``<!-- snippet: name -->`` in ``doc``."""
    match = re.search(rf"<!-- snippet: {re.escape(name)} -->\s*```[a-z]*\n(.*?)\n```", doc.read_text(), re.S)
    assert match, f"no snippet {name!r} in {doc}"
    return match.group(1)


def with_constants(code: str, **values) -> str:
    """``code`` with each top-level ``NAME = ...`` line set to ``NAME = value`` (each must occur once)."""
    for name, value in values.items():
        code, count = re.subn(rf"^{name} = .*$", f"{name} = {value!r}", code, flags=re.M)
        assert count == 1, f"{name} = ... occurs {count} times in the snippet"
    return code


def commands(code: str) -> list[str]:
    """The shell commands of a bash block (continuation lines joined)."""
    return [line.strip() for line in code.replace("\\\n", " ").splitlines() if line.strip()]
