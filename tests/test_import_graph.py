"""The import graph of the installed packages: no cycle, and the layers import downwards only.

Every module under the package-dir folders of ``pyproject.toml`` (``pectoral_gym/``, ``agents/``, ``scaling/``,
``hardware/``) is parsed with :mod:`ast` (no code runs); each ``import`` and ``from ... import`` of a
``pectoral_gym`` module counts, at the top level or deferred inside a function, and so does a ``TYPE_CHECKING``
import: a cycle is a cycle however it is dodged at run time. The layers: the core
(``pectoral_gym`` outside the three folders) imports none of ``agents``, ``scaling``, ``hardware``; ``agents`` and
``scaling`` import nothing from ``hardware``.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CORE = "pectoral_gym"
OUTER = ("pectoral_gym.agents", "pectoral_gym.scaling", "pectoral_gym.hardware")
HARDWARE = "pectoral_gym.hardware"

# agents/scaling -> hardware imports still allowed: none (the fin rules and the run-log format live in the core).
PENDING_HARDWARE_IMPORTS: frozenset[tuple[str, str]] = frozenset()


def package_dirs() -> dict[str, Path]:
    """Package name -> folder, from ``[tool.setuptools.package-dir]`` (read by hand: no tomllib on Python 3.10)."""
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    section = text.split("[tool.setuptools.package-dir]", 1)[1].split("\n[", 1)[0]
    pairs = re.findall(r'^\s*"?([\w.]+)"?\s*=\s*"([^"]+)"', section, flags=re.MULTILINE)
    assert pairs, "pyproject.toml has no [tool.setuptools.package-dir] entries"
    return {name: ROOT / folder for name, folder in pairs}


def modules() -> dict[str, Path]:
    """Every module's dotted name -> its file (a package's ``__init__.py`` under the package's own name)."""
    found: dict[str, Path] = {}
    for package, folder in package_dirs().items():
        for path in sorted(folder.rglob("*.py")):
            parts = path.relative_to(folder).with_suffix("").parts
            if any(part.startswith(".") or part == "__pycache__" for part in parts):
                continue
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join((package, *parts))] = path
    return found


def _resolve(name: str, known: dict[str, Path]) -> str | None:
    """The longest known module that ``name`` is or lies in (``a.b.c`` -> ``a.b`` if ``c`` is a name in it)."""
    while name:
        if name in known:
            return name
        name = name.rpartition(".")[0]
    return None


def imports(module: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The project modules that ``module`` imports, anywhere in its file."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join([*anchor, *([base] if base else [])])
            names = [f"{base}.{alias.name}" for alias in node.names] + [base]
        else:
            continue
        for name in names:
            if name.split(".")[0] == CORE and (target := _resolve(name, known)) is not None and target != module:
                out.add(target)
    # a package's __init__ is imported with any of its modules: not an edge of the module's own choosing
    return out


def graph() -> dict[str, set[str]]:
    known = modules()
    edges = {module: imports(module, path, known) for module, path in known.items()}
    for module, targets in edges.items():  # "from pkg import sub" names a module, "import pkg.sub" its parents
        edges[module] = {t for t in targets if not (module.startswith(t + ".") and known[t].name == "__init__.py")}
    return edges


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = 0

    def visit(root: str) -> None:  # iterative: the graph is deep enough to worry the recursion limit
        nonlocal counter
        work = [(root, iter(sorted(edges.get(root, ()))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges.get(child, ())))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))

    for module in sorted(edges):
        if module not in index:
            visit(module)
    return found


def _in(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def test_every_package_dir_folder_holds_its_modules():
    known = modules()
    for package, folder in package_dirs().items():
        assert folder.is_dir() and package in known, f"{package} -> {folder}"
    assert len(known) > 100  # the walk found the project, not an empty folder


def test_no_import_cycle():
    found = cycles(graph())
    assert found == [], "import cycles (deferred and TYPE_CHECKING imports count):\n" + "\n".join(
        " <-> ".join(c) for c in found)


def test_the_core_imports_no_outer_package():
    bad = sorted((m, t) for m, targets in graph().items() if not any(_in(m, p) for p in OUTER)
                 for t in targets if any(_in(t, p) for p in OUTER))
    assert bad == []


def test_agents_and_scaling_import_nothing_from_hardware():
    edges = graph()
    bad = {(m, t) for m, targets in edges.items() if not _in(m, HARDWARE) and any(_in(m, p) for p in OUTER)
           for t in targets if _in(t, HARDWARE)}
    assert sorted(bad - PENDING_HARDWARE_IMPORTS) == []
    stale = PENDING_HARDWARE_IMPORTS - bad
    assert not stale, f"allowed imports that no longer exist (remove them from the list): {sorted(stale)}"


def test_the_checker_sees_cycles_and_deferred_imports(tmp_path):
    # the checker itself: a two-module cycle through a deferred import, and a chain without one
    assert cycles({"a": {"b"}, "b": {"a"}, "c": {"a"}}) == [["a", "b"]]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    path = tmp_path / "m.py"
    path.write_text("def f():\n    from pectoral_gym.x import y\nif False:\n    import pectoral_gym.z\n")
    known = {"pectoral_gym.m": path, "pectoral_gym.x": path, "pectoral_gym.z": path}
    assert imports("pectoral_gym.m", path, known) == {"pectoral_gym.x", "pectoral_gym.z"}
