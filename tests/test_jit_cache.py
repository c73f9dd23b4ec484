"""The kernels' disk cache follows every source they compile from (``pectoral_gym.model.jit_cache``).

numba keys its cache on the file of the cached function only; an edit of a
function in another module, which the cached kernel calls, must still reach it.
The edits are made in a scratch copy of the package, with its own cache folder.
"""

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pectoral_gym.model.jit_cache import source_tree

PACKAGE = Path(__file__).resolve().parents[1] / "pectoral_gym"

# strokes.fin_forcing (a cached kernel) calls dynamics.fin_force_right, which calls dynamics.fin_force_at.
PROBE = """
import numpy as np
import pectoral_gym
from pectoral_gym.model import strokes as st
from pectoral_gym.model.params import FishParams, coefficient_vector
fins = np.zeros((1, 2, st.FIN_FIELDS))
fins[0, :, st.DURATION] = 0.5
fins[0, :, st.ANGLE_FROM] = -0.5
fins[0, :, st.ANGLE_TO] = 0.5
print("package", pectoral_gym.__file__)
print("force", repr(st.fin_forcing(fins, coefficient_vector(FishParams())[None], 0, 0.1)[0]))
"""


def _run(src: Path, cache: Path) -> tuple[float, bool]:
    """The probe's force in a fresh process, and whether ``fin_forcing`` came from the disk cache."""
    env = {**os.environ, "PYTHONPATH": str(src), "NUMBA_CACHE_DIR": str(cache), "NUMBA_DEBUG_CACHE": "1"}
    done = subprocess.run([sys.executable, "-c", PROBE], env=env, cwd=src, capture_output=True, text=True,
                          check=True, timeout=600)
    lines = done.stdout.splitlines()
    assert f"package {src / 'pectoral_gym' / '__init__.py'}" in lines  # the copy, not the checkout
    loaded = any("data loaded" in line and "strokes.fin_forcing-" in line for line in lines)
    return float(next(line.split()[1] for line in lines if line.startswith("force "))), loaded


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert text.count(old) == 1, f"{old!r} not once in {path.name}"
    path.write_text(text.replace(old, new))


def test_edit_in_a_called_module_recompiles_the_caller(tmp_path):
    src = tmp_path / "src"
    shutil.copytree(PACKAGE, src / "pectoral_gym", ignore=shutil.ignore_patterns("__pycache__", "*.nb[ic]"))
    cache = tmp_path / "numba-cache"

    force, loaded = _run(src, cache)
    assert not loaded and force != 0.0

    cli = src / "pectoral_gym" / "tools" / "cli.py"
    cli.write_text(cli.read_text() + "# an edit outside the kernel's sources\n")
    assert _run(src, cache) == (force, True)  # the next process runs the cached kernel

    _edit(src / "pectoral_gym" / "model" / "dynamics.py", "    return fx, fy\n", "    return 2.0 * fx, 2.0 * fy\n")
    assert _run(src, cache) == (2.0 * force, False)  # compiled afresh, no cache deleted


@pytest.fixture
def package(tmp_path):
    """A package ``pkg`` whose module ``a`` imports some of its siblings in every form."""
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    files = {
        "__init__.py": "from pkg import e\n",
        "a.py": "import numpy\nfrom pkg.b import f\nfrom . import c\nfrom .sub import g\n",
        "b.py": "def f():\n    import pkg.d\n",
        "c.py": "",
        "d.py": "",
        "e.py": "",
        "sub/__init__.py": "g = 1\n",
    }
    for name, text in files.items():
        (pkg / name).write_text(text)
    return pkg


def test_source_tree_follows_the_package_imports(package):
    tree = source_tree("pkg.a", package / "a.py")
    assert tree == {"pkg.a": package / "a.py", "pkg.b": package / "b.py", "pkg.c": package / "c.py",
                    "pkg.d": package / "d.py", "pkg.sub": package / "sub" / "__init__.py"}


def test_source_tree_follows_imports_into_subpackages_kept_in_other_folders():
    # pectoral_gym.hardware and .agents live in the checkout's hardware/ and agents/ (package-dir): the
    # tree of a robot module reaches the agents' and the model's modules, each at the file Python imports.
    spec = importlib.util.find_spec("pectoral_gym.hardware.deploy")
    tree = source_tree("pectoral_gym.hardware.deploy", spec.origin)
    for name in ("pectoral_gym.agents.baselines", "pectoral_gym.hardware.env", "pectoral_gym.model.params"):
        assert name in tree
    for name, path in tree.items():
        assert path == Path(importlib.util.find_spec(name).origin), name
