"""The documentation site and the project files: strict build, API pages' coverage, LICENSE, CHANGELOG, CITATION.

The site build needs the docs extra (``pip install -e ".[docs]"``, part of dev); without it that test is skipped.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
API_PAGES = ROOT / "docs" / "reference" / "api"
HOOKS = ROOT / "docs" / "hooks"
DIRECTIVE = re.compile(r"^::: (?P<identifier>[\w.]+)[ \t]*\n(?P<options>(?:[ \t]+\S.*\n?)*)", re.MULTILINE)


def pyproject() -> dict:
    if sys.version_info >= (3, 11):
        import tomllib
    else:
        tomllib = pytest.importorskip("tomli")
    return tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


class _ConfigLoader(yaml.SafeLoader):
    """Reads mkdocs.yml with MkDocs' own tags (``!relative``, ``!ENV``) as plain values."""


_ConfigLoader.add_multi_constructor("!", lambda loader, suffix, node: loader.construct_scalar(node)
                                    if isinstance(node, yaml.ScalarNode) else None)


def mkdocs_config() -> dict:
    return yaml.load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"), Loader=_ConfigLoader)


def load_hook(name: str):
    spec = importlib.util.spec_from_file_location(f"docs_hook_{name}", HOOKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def api_directives() -> dict[str, bool]:
    """Identifier of every ``::: identifier`` of the API pages -> whether its submodules are rendered with it."""
    plugin = next(entry["mkdocstrings"] for entry in mkdocs_config()["plugins"]
                  if isinstance(entry, dict) and "mkdocstrings" in entry)
    handler = plugin["handlers"]["python"]["options"]
    default = handler.get("show_submodules", False)
    found: dict[str, bool] = {}
    for page in sorted(API_PAGES.glob("*.md")):
        for match in DIRECTIVE.finditer(page.read_text(encoding="utf-8")):
            options = (yaml.safe_load(textwrap.dedent(match["options"])) or {}).get("options", {})
            assert match["identifier"] not in found, f"{match['identifier']} is on two API pages"
            found[match["identifier"]] = options.get("show_submodules", default)
    return found


def source_modules() -> list[str]:
    """Every public module of the distribution, from the folders pyproject.toml maps to its packages."""
    package_dirs = pyproject()["tool"]["setuptools"]["package-dir"]
    modules = []
    for package in pyproject()["tool"]["setuptools"]["packages"]:
        owner = max((name for name in package_dirs if package == name or package.startswith(name + ".")), key=len)
        folder = ROOT / package_dirs[owner] / Path(*package[len(owner):].split(".")[1:])
        modules.append(package)
        modules += [f"{package}.{path.stem}" for path in sorted(folder.glob("*.py")) if not path.stem.startswith("_")]
    return modules


def test_every_module_is_on_an_api_page_and_resolves():
    directives = api_directives()
    assert directives, "no ::: directives found in docs/reference/api"
    for identifier in directives:
        assert importlib.util.find_spec(identifier) is not None, f"the API pages name {identifier}: no such module"
    missing = [module for module in source_modules() if not any(
        module == identifier or (submodules and module.startswith(identifier + "."))
        for identifier, submodules in directives.items())]
    assert not missing, f"modules on no API page (docs/reference/api): {missing}"


def test_nav_lists_every_api_page():
    nav = yaml.safe_dump(mkdocs_config()["nav"])
    for page in API_PAGES.glob("*.md"):
        assert f"reference/api/{page.name}" in nav, f"{page.name} is not in mkdocs.yml's nav"


def test_site_builds_strictly(tmp_path):
    for module in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed (pip install -e '.[docs]'); the site cannot be built")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    site = tmp_path / "site"
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                            cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, f"mkdocs build --strict failed:\n{result.stdout}\n{result.stderr}"
    for identifier in api_directives():  # each documented module has its anchor on the built site
        assert any(f'id="{identifier}"' in page.read_text(encoding="utf-8")
                   for page in (site / "reference" / "api").rglob("index.html")), identifier
    changelog = (site / "changelog" / "index.html").read_text(encoding="utf-8")
    assert pyproject()["project"]["version"] in changelog, "docs/changelog.md does not include CHANGELOG.md"


def test_project_files_agree_with_the_version():
    version = pyproject()["project"]["version"]
    licence = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert licence.startswith("MIT License") and "pectoral-gym developers" in licence
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert citation["cff-version"] == "1.2.0"
    assert str(citation["version"]) == version
    assert citation["references"][0]["title"] == "Averaged Modeling of Pectoral Fin-Actuated Robotic Fish"
    changelog = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert re.search(rf"^## \[{re.escape(version)}\] - \d{{4}}-\d{{2}}-\d{{2}}$", changelog, re.MULTILINE), \
        f"CHANGELOG.md has no section for {version}"
    assert re.search(r"^## \[Unreleased\]$", changelog, re.MULTILINE)

    import pectoral_gym

    assert pectoral_gym.__version__ == version, "pectoral_gym.__version__ differs from pyproject.toml's version"


def test_repository_links_point_at_the_web_view(tmp_path):
    hook = load_hook("source_links")
    web = ("https://example.org/repo", "main")
    docs = ROOT / "docs"
    text = ("See [ppo.yml](../agents/hyperparams/ppo.yml \"the file\"), [the agents](../agents/),\n"
            "[spread\nover lines](../pyproject.toml#L1), [a page](hardware.md), [gone](../no/such/file.py),\n"
            "![demo](../docs/images/demo_trajectories.png) and [web](https://example.org).\n"
            "```\n[in code](../pyproject.toml)\n```\n[ref]: ../README.md\n")
    out = hook.rewrite_links(text, "agents.md", docs, ROOT, web)
    assert '[ppo.yml](https://example.org/repo/blob/main/agents/hyperparams/ppo.yml "the file")' in out
    assert "[the agents](https://example.org/repo/tree/main/agents)" in out
    assert "[spread\nover lines](https://example.org/repo/blob/main/pyproject.toml#L1)" in out
    assert "[a page](hardware.md)" in out and "[gone](../no/such/file.py)" in out
    assert "![demo](../docs/images/demo_trajectories.png)" in out  # inside docs/: the site has it
    assert "[in code](../pyproject.toml)" in out
    assert "[ref]: https://example.org/repo/blob/main/README.md" in out
    assert hook.rewrite_links("[x](../../pyproject.toml)", "guide/page.md", docs, ROOT, web) == \
        "[x](https://example.org/repo/blob/main/pyproject.toml)"


def test_sphinx_roles_become_inline_code():
    pytest.importorskip("griffe")
    roles = load_hook("griffe_roles")
    assert roles.strip_roles("See :class:`~pectoral_gym.model.params.FishParams` and :mod:`.clock`.") == \
        "See `FishParams` and `clock`."
    assert roles.strip_roles(":func:`pectoral_gym.registration.register_envs`") == \
        "`pectoral_gym.registration.register_envs`"
