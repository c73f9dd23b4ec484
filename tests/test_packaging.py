"""The distribution as a user installs it: one import root, package data, a clean non-editable install.

The wheel is built from the checkout's files (``git ls-files``) with the running venv's setuptools
(``pip wheel --no-build-isolation``: no index needed) and installed into fresh venvs that see this venv's
third-party packages but neither the checkout nor its editable install; every check there runs from a folder
outside the checkout.
"""

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
SCRIPTS = sorted(PYPROJECT["project"]["scripts"])
# the checkout's folders and the packages they install as
FOLDERS = {"pectoral_gym": "pectoral_gym", "agents": "pectoral_gym.agents", "scaling": "pectoral_gym.scaling",
           "hardware": "pectoral_gym.hardware"}
# this distribution's entries in a site-packages folder: hidden from the fresh venvs
OWN = ("pectoral_gym", "pectoral-gym", "__editable__", "__editable___pectoral_gym")


def _run(args, cwd, timeout=300, **env):
    """``args`` with a clean environment (no PYTHONPATH) from ``cwd``."""
    clean = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP")}
    return subprocess.run(args, cwd=cwd, env={**clean, "MPLBACKEND": "Agg", **env}, capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    """The wheel built from the checkout's files (a copy, so the checkout gets no build/ folder)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs a git checkout (the wheel is built from the files git lists)")
    listed = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT, capture_output=True,
                            check=True).stdout.decode().split("\0")
    src = tmp_path_factory.mktemp("src")
    for name in filter(None, listed):
        if (ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    out = tmp_path_factory.mktemp("wheel")
    built = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q",
                  "-w", str(out), str(src)], cwd=out)
    assert built.returncode == 0, built.stderr[-3000:]
    (found,) = out.glob("pectoral_gym-*.whl")
    return found


def _fresh_venv(root: Path, wheel: Path, hide: tuple[str, ...] = ()) -> Path:
    """A venv with ``wheel`` installed and this venv's third-party packages (less ``hide``) visible; its python.

    Those packages are seen through a folder of links named in a ``.pth`` file: the entries of this
    distribution (the editable install's finder and metadata) and ``hide`` are left out, and the ``.pth``
    files among them are not run (a ``.pth`` line adds a path, not a site folder).
    """
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(root / "venv")], check=True)
    python = root / "venv" / "bin" / "python"
    view = root / "deps"
    view.mkdir()
    skip = OWN + hide
    for site in dict.fromkeys([sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]):
        for entry in Path(site).iterdir():
            if not entry.name.startswith(skip) and not entry.name.endswith(".pth") and not (view / entry.name).exists():
                (view / entry.name).symlink_to(entry)
    purelib = _run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=root)
    (Path(purelib.stdout.strip()) / "deps.pth").write_text(f"{view}\n")
    installed = _run([str(python), "-m", "pip", "install", "--no-deps", "--no-index", "-q", str(wheel)], cwd=root)
    assert installed.returncode == 0, installed.stderr[-3000:]
    return python


@pytest.fixture(scope="module")
def venv(wheel, tmp_path_factory):
    """A fresh venv with the wheel installed (not editable), and a folder outside the checkout to run in."""
    root = tmp_path_factory.mktemp("venv")
    return _fresh_venv(root, wheel), root


def test_the_wheel_installs_one_top_level_package_with_its_data(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    assert {n.split("/")[0] for n in names} == {"pectoral_gym", wheel.name.split("-py")[0] + ".dist-info"}
    top_level = [n for n in names if n.endswith(".dist-info/top_level.txt")]
    assert not top_level or zipfile.ZipFile(wheel).read(top_level[0]).decode().split() == ["pectoral_gym"]
    # every module of the checkout's package folders, where its package installs it
    for folder, package in FOLDERS.items():
        for path in (ROOT / folder).rglob("*.py"):
            if "__pycache__" not in path.parts:
                assert "/".join([*package.split("."), *path.relative_to(ROOT / folder).parts]) in names, path
    for data in ("pectoral_gym/data/scaling_coefficients.json",
                 "pectoral_gym/py.typed", "pectoral_gym/agents/hyperparams/ppo.yml",
                 "pectoral_gym/agents/hyperparams/sac.yml"):
        assert data in names


CHECK = """
import sys
from pathlib import Path
import gymnasium as gym
import pectoral_gym
import pectoral_gym.agents.training.config as config
import pectoral_gym.hardware.radio.protocol, pectoral_gym.scaling.cli
prefix = Path(sys.prefix).resolve()
for name in ("pectoral_gym", "pectoral_gym.agents", "pectoral_gym.scaling", "pectoral_gym.hardware"):
    assert Path(sys.modules[name].__file__).resolve().is_relative_to(prefix), (name, sys.modules[name].__file__)
assert not {"agents", "scaling", "hardware"} & set(sys.modules)
assert (Path(config.__file__).parent.parent / "hyperparams" / "ppo.yml").is_file()
env = gym.make("PectoralFish-Averaged-v0")
obs, info = env.reset(seed=0)
assert env.observation_space.contains(obs)
print("ok")
"""


def test_a_clean_install_imports_and_makes_an_env_from_another_folder(venv, tmp_path):
    python, root = venv
    done = _run([str(python), "-c", CHECK], cwd=tmp_path, NUMBA_CACHE_DIR=str(root / "numba"))
    assert done.returncode == 0 and done.stdout.split() == ["ok"], done.stderr[-3000:]


@pytest.mark.parametrize("script", SCRIPTS)
def test_every_console_script_of_a_clean_install_answers_help(venv, tmp_path, script):
    python, root = venv
    done = _run([str(python.parent / script), "--help"], cwd=tmp_path, NUMBA_CACHE_DIR=str(root / "numba"))
    assert done.returncode == 0 and "usage:" in done.stdout, (script, done.stderr[-3000:])


def test_the_checkout_folders_are_importable_by_one_name_only():
    done = _run([sys.executable, "-c", "import pectoral_gym.agents, pectoral_gym.hardware, pectoral_gym.scaling"],
                cwd=ROOT)
    assert done.returncode == 0, done.stderr[-3000:]
    for folder, package in FOLDERS.items():
        if folder == package:
            continue
        done = _run([sys.executable, "-c", f"import {folder}"], cwd=ROOT)  # the checkout's root is on sys.path
        assert done.returncode != 0 and f"ImportError: import {package}, not {folder}" in done.stderr, done.stderr


NOT_INSTALLED = """
import sys
from pathlib import Path
root, site_dirs = Path(sys.argv[1]), sys.argv[2:]
sys.path[:0] = [str(root), *site_dirs]  # python -I -S: no .pth files ran, so no editable finder either
assert "editable" not in repr(sys.meta_path), sys.meta_path
import pectoral_gym.agents.training.config as config
import pectoral_gym.hardware.radio.protocol, pectoral_gym.scaling.cli
for name in ("pectoral_gym.agents", "pectoral_gym.scaling", "pectoral_gym.hardware"):
    assert Path(sys.modules[name].__file__) == root / name.split(".")[1] / "__init__.py", sys.modules[name].__file__
assert not {"agents", "scaling", "hardware"} & set(sys.modules)
files = [Path(m.__file__).resolve() for n, m in list(sys.modules.items())
         if n.startswith("pectoral_gym") and getattr(m, "__file__", None)]
assert len(files) == len(set(files)), "a module loaded under two names"
from pectoral_gym.model.jit_cache import source_tree
tree = source_tree(config.__name__, config.__file__)  # what a kernel's cache key would walk
assert tree["pectoral_gym.agents.training.zoo_format"] == root / "agents" / "training" / "zoo_format.py", tree
assert None not in tree.values(), tree
try:
    import scaling
except ImportError as error:
    assert "import pectoral_gym.scaling, not scaling" in str(error), error
else:
    raise AssertionError("the scaling/ folder imported by a second name")
print("ok")
"""


def test_a_checkout_that_is_not_installed_imports_the_apps_under_pectoral_gym(tmp_path):
    # The checkout's root on sys.path, the venv's third-party packages, and neither the editable install's
    # finder (python -S runs no .pth file) nor the caller's environment (-I).
    site_dirs = [p for p in {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]} if Path(p).is_dir()]
    done = _run([sys.executable, "-I", "-S", "-c", NOT_INSTALLED, str(ROOT), *site_dirs], cwd=tmp_path)
    assert done.returncode == 0 and done.stdout.split() == ["ok"], done.stderr[-3000:]


WITHOUT_PLOTS = """
import sys
import gymnasium as gym
import pectoral_gym
from pectoral_gym.tools.optional import require
env = gym.make("PectoralFish-Averaged-v0")
env.reset(seed=0)
assert not {"matplotlib", "tqdm"} & {name.split(".")[0] for name in sys.modules}, "imported"
for name in ("matplotlib", "tqdm"):
    try:
        require(name)
    except ModuleNotFoundError as error:
        assert "pectoral-gym[plots]" in str(error), error
    else:
        raise AssertionError(name + " is visible")
print("ok")
"""


def test_the_model_library_and_the_envs_need_neither_matplotlib_nor_tqdm(wheel, tmp_path_factory, tmp_path):
    root = tmp_path_factory.mktemp("venv-core")
    python = _fresh_venv(root, wheel, hide=("matplotlib", "mpl_toolkits", "pylab", "tqdm"))
    done = _run([str(python), "-c", WITHOUT_PLOTS], cwd=tmp_path, NUMBA_CACHE_DIR=str(root / "numba"))
    assert done.returncode == 0 and done.stdout.split() == ["ok"], done.stderr[-3000:]
    assert _run([str(python.parent / "pectoral-fish"), "--help"], cwd=tmp_path).returncode == 0
