"""MkDocs hook: the API pages read the sources laid out as the installed package.

The distribution installs the repository's ``agents/``, ``scaling/`` and ``hardware/`` folders as
``pectoral_gym.agents``, ``.scaling`` and ``.hardware`` (``[tool.setuptools.package-dir]`` in ``pyproject.toml``).
Griffe, which mkdocstrings uses, reads packages from folders and would find ``pectoral_gym`` without them. This
hook copies the Python sources into a temporary folder in the installed layout and makes it the first search
path of mkdocstrings' Python handler, so the API pages are built from the checkout, installed or not. A module
that an API page names and that is not there fails the strict build.
"""

from __future__ import annotations

import atexit
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

from mkdocs.plugins import event_priority

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - the docs extra brings tomli on Python 3.10
    import tomli as tomllib

PACKAGE = "pectoral_gym"
_COPIED = shutil.ignore_patterns("__pycache__", "*.pyc", "*.json", "*.yml", "*.nbi", "*.nbc")


def package_dirs(root: Path) -> dict[str, Path]:
    """Package name -> source folder, from ``pyproject.toml``'s ``[tool.setuptools.package-dir]``."""
    pyproject = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    mapping = pyproject["tool"]["setuptools"]["package-dir"]
    return {name: root / folder for name, folder in mapping.items()}


def lay_out(root: Path, target: Path) -> Path:
    """Copy the package's sources under ``target`` in the installed layout; return ``target``."""
    for name, folder in sorted(package_dirs(root).items(), key=lambda item: item[0].count(".")):
        if not name.startswith(PACKAGE):
            continue
        destination = target.joinpath(*name.split("."))
        shutil.copytree(folder, destination, ignore=_COPIED, dirs_exist_ok=True)
    return target


@event_priority(100)  # before mkdocstrings' on_config, which creates the handler with its search paths
def on_config(config: Any) -> Any:
    """MkDocs event: lay the sources out and make them the Python handler's search path."""
    root = Path(config.config_file_path).resolve().parent
    target = Path(tempfile.mkdtemp(prefix="pectoral-gym-api-"))
    atexit.register(shutil.rmtree, target, ignore_errors=True)
    lay_out(root, target)
    plugin = config.plugins["mkdocstrings"]
    python = plugin.config.handlers.setdefault("python", {})
    python["paths"] = [str(target)]
    return config
