"""The layers: the core never imports the robot stack, the controllers or the scaling tools; the controllers and the
scaling tools take the robot's rules from the core, not from the robot stack.

Read from the source (every import statement, deferred ones included), so a local import cannot hide an edge.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
OUTER = ("pectoral_gym.hardware", "pectoral_gym.agents", "pectoral_gym.scaling")

#: Modules of agents/ and scaling/ still allowed to import the robot stack: the deployment study runs it (until the
#: robot stack offers it a library entry point); nothing else may.
RUNS_THE_ROBOT_STACK = frozenset({"agents/studies/deployment.py"})


def _imports(path: Path) -> list[tuple[int, str]]:
    """``(line, module)`` of every absolute import in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module))
        elif isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
    return found


def _offending(folder: str, forbidden: tuple[str, ...], allowed: frozenset[str] = frozenset()) -> list[str]:
    """``file:line imports module`` for every import of a ``forbidden`` package under ``folder``."""
    out = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel in allowed:
            continue
        out += [f"{rel}:{line} imports {module}" for line, module in _imports(path)
                if module.startswith(forbidden)]
    return out


def test_the_core_imports_nothing_from_the_robot_stack_the_controllers_or_the_scaling_tools():
    assert _offending("pectoral_gym", OUTER) == []


@pytest.mark.parametrize("folder", ["agents", "scaling"])
def test_controllers_and_scaling_tools_take_the_robots_rules_from_the_core(folder):
    assert _offending(folder, ("pectoral_gym.hardware",), RUNS_THE_ROBOT_STACK) == []


def test_the_check_sees_a_deferred_import(tmp_path):
    # A test that cannot fail is a defect: an import inside a function is an edge too.
    module = tmp_path / "m.py"
    module.write_text("def f():\n    from pectoral_gym.hardware.radio import firmware\n    return firmware\n")
    assert _imports(module) == [(2, "pectoral_gym.hardware.radio")]
