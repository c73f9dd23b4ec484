"""The contributor docs' layout is the code's, and every folder imports under the name the docs give it."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

from pectoral_gym.tools import layout

tomllib = pytest.importorskip("tomllib")  # Python 3.11+

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / layout.DEFAULT_PATH
PACKAGE_DIR = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
ROW = re.compile(r"^\| `(?P<name>[\w.]+)` \| `(?P<folder>[\w./]+)/` \|", re.M)


def _documented() -> dict[str, str]:
    """The layout table of the page: import name -> folder."""
    return {m["name"]: m["folder"] for m in ROW.finditer(PAGE.read_text())}


def _package_folders() -> dict[str, str]:
    """Every folder with an ``__init__.py`` under the mapped folders -> its import name, from package-dir alone."""
    found = {}
    for name, top in PACKAGE_DIR.items():
        for init in (ROOT / top).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / top)
            if any(part.startswith((".", "__")) for part in rel.parts):
                continue
            found[init.parent.relative_to(ROOT).as_posix()] = ".".join((name, *rel.parts))
    return found


def test_the_page_holds_the_generated_layout():
    page = PAGE.read_text()
    assert layout.replace_section(page, layout.layout_markdown(ROOT)) == page, (
        "docs/contributing.md's layout is stale: run python -m pectoral_gym.tools.layout --write")


def test_the_check_command_agrees(capsys):
    assert layout.main(["--check", "--root", str(ROOT)]) == 0


def test_every_package_folder_is_in_the_table_under_the_name_it_imports_as():
    documented = _documented()
    folders = _package_folders()
    assert {"pectoral_gym", "pectoral_gym.sensing", "pectoral_gym.scaling.calibration",
            "pectoral_gym.hardware.radio"} <= set(documented)
    for folder, name in sorted(folders.items()):
        assert documented.get(name) == folder, f"{folder}/ imports as {name}: the layout table says " \
            f"{documented.get(name)!r}"
        package = importlib.import_module(name)
        assert Path(package.__path__[0]).resolve() == (ROOT / folder).resolve(), name
    assert set(documented) == set(folders.values()), "the table lists a package that is no folder"


def test_the_mapping_table_is_pyprojects_package_dir():
    text = PAGE.read_text()
    section = text[text.index("## Folders and import names"):]
    rows = dict(re.findall(r"^\| `([\w/]+)/` \| `([\w.]+)` \|$", section, re.M))
    assert {name: folder for folder, name in rows.items()} == PACKAGE_DIR


def test_folder_of_follows_the_longest_mapped_prefix():
    dirs = {"pectoral_gym": "pectoral_gym", "pectoral_gym.hardware": "hardware"}
    assert layout.folder_of("pectoral_gym.hardware.radio", dirs) == "hardware/radio"
    assert layout.folder_of("pectoral_gym.hardware", dirs) == "hardware"
    assert layout.folder_of("pectoral_gym.envs.tasks", dirs) == "pectoral_gym/envs/tasks"
    assert layout.folder_of("pectoral_gym.hardwarex", dirs) == "pectoral_gym/hardwarex"


def test_the_view_is_the_installed_tree(tmp_path):
    top = layout.write_view(ROOT, tmp_path / "view")
    for folder, name in _package_folders().items():
        linked = top.joinpath(*name.split(".")[1:], "__init__.py")
        assert linked.resolve() == (ROOT / folder / "__init__.py").resolve(), name
    assert (top / "registration.py").resolve() == (ROOT / "pectoral_gym" / "registration.py").resolve()
    with pytest.raises(SystemExit, match="exists"):
        layout.write_view(ROOT, tmp_path / "view")


def test_a_page_without_the_markers_is_an_error():
    with pytest.raises(SystemExit, match="no section"):
        layout.replace_section("# a page\n", "x")
