"""The TorchRL and RLlib snippets of docs/guide/trainers.md, run as they are written (sizes shrunk by their constants).

The RLlib snippet needs ``ray[rllib]``, which pins gymnasium 1.2.2: it runs in ``.ci/run``'s ``.venv-rllib`` and is
skipped elsewhere. The rl-baselines3-zoo snippet runs in ``tests/test_config_zoo.py``, the page's other recipes in
``tests/test_trainer_recipes.py``.
"""

import importlib.util
import os
import subprocess
import sys

import pytest
from doc_snippets import ROOT, snippet, with_constants


def run_python(code, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-4000:]
    return done.stdout


def _has(module):
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


@pytest.mark.skipif(not _has("torchrl"), reason="torchrl not installed (clients extra)")
def test_torchrl_snippet_trains(tmp_path):
    out = run_python(with_constants(snippet("torchrl"), FRAMES_PER_BATCH=64, TOTAL_FRAMES=128), tmp_path)
    lines = [line for line in out.splitlines() if line.startswith("mean reward per step")]
    assert len(lines) == 2  # two batches of 64 frames, one optimiser step each
    assert (tmp_path / "torchrl_actor.pt").is_file()


def _rllib_usable():
    try:
        import ray.rllib  # noqa: F401
    except Exception:  # noqa: BLE001 - the ray wheel ships rllib's code without its dependencies
        return False
    return True


@pytest.mark.skipif(not _rllib_usable(), reason="ray[rllib] not installed: it pins gymnasium 1.2.2, so .ci/run runs "
                                                "this test in a venv of its own (.venv-rllib)")
def test_rllib_snippet_trains_with_the_module_id(tmp_path):
    out = run_python(with_constants(snippet("rllib"), ITERATIONS=1, BATCH=256), tmp_path)
    lines = [line for line in out.splitlines() if line.startswith("0 ")]
    assert len(lines) == 1, out[-2000:]
    assert (tmp_path / "rllib_checkpoint").is_dir()
