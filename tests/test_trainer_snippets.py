"""The TorchRL and RLlib snippets of docs/guide/trainers.md, run as they are written (sizes shrunk by their constants).

The RLlib snippet needs ``ray[rllib]``, which pins gymnasium 1.2.2: it runs in ``.ci/run``'s ``.venv-rllib`` and is
skipped elsewhere. The rl-baselines3-zoo snippet runs in ``tests/test_config_zoo.py``, the page's other recipes in
``tests/test_trainer_recipes.py``.
"""

import importlib.util
import os
import re
import subprocess
import sys

import numpy as np
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
    assert all(re.fullmatch(r"mean reward per step -?[\d.]+, stops in the band \d+", line) for line in lines), lines
    assert (tmp_path / "torchrl_actor.pt").is_file()
    assert "torch.set_num_threads(1)" in snippet("torchrl") and "LATEST_AVERAGED" in snippet("torchrl")


@pytest.mark.skipif(not _has("torchrl"), reason="torchrl not installed (clients extra)")
def test_torchrl_snippet_env_keeps_the_cost():
    # the snippet's env (its imports and env lines, as written) against the Gymnasium env stepped with the same
    # actions: the same observations, and the cost of every step, the band's stops among them
    import gymnasium as gym
    from torchrl.envs.utils import check_env_specs

    lines = [line for line in snippet("torchrl").splitlines()
             if line.startswith(("import ", "from ", "env = ", "env.set_info_dict_reader"))]
    namespace = {}
    exec("\n".join(lines), namespace)  # noqa: S102 - the page's code
    env = namespace["env"]
    check_env_specs(env)
    stops = 0
    for seed in range(6):
        env.set_seed(seed)
        rollout = env.rollout(240, break_when_any_done=True)
        reference = gym.make(namespace["LATEST_AVERAGED"])
        reference.reset(seed=seed)  # TorchRL's set_seed resets with the seed; its rollout resets again
        first, _ = reference.reset()
        np.testing.assert_array_equal(rollout["observation"][0].numpy(), first)
        for action, cost, obs in zip(rollout["action"].numpy(), rollout["next", "cost"].numpy(),
                                     rollout["next", "observation"].numpy(), strict=True):
            step_obs, _, _, _, info = reference.step(action)
            np.testing.assert_array_equal(obs, step_obs)
            assert cost == info["cost"]
        stops += int(rollout["next", "cost"].sum())
    assert stops >= 1  # the check sees a cost of 1


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


@pytest.mark.skipif(not _has("torchrl"), reason="torchrl not installed (clients extra)")
def test_torchrl_reads_the_graded_band_cost():
    # the page's pointer: GymWrapper of a BandCost-wrapped env with a reader of both keys
    import gymnasium as gym
    import torch
    from torchrl.data import Unbounded
    from torchrl.envs import GymWrapper, default_info_dict_reader
    from torchrl.envs.utils import check_env_specs

    from pectoral_gym.envs.cost import BandCost
    from pectoral_gym.versions import LATEST_AVERAGED

    env = GymWrapper(BandCost(gym.make(LATEST_AVERAGED)))
    env.set_info_dict_reader(default_info_dict_reader(
        ["cost", "band_cost"], spec={key: Unbounded((), dtype=torch.float64) for key in ("cost", "band_cost")}))
    check_env_specs(env)
    graded = 0.0
    for seed in range(4):
        env.set_seed(seed)
        rollout = env.rollout(240, break_when_any_done=True)
        cost, band_cost = rollout["next", "cost"].numpy(), rollout["next", "band_cost"].numpy()
        assert np.all((band_cost >= 0) & (band_cost <= 1)) and np.all(band_cost[cost == 1.0] == 1.0)
        graded += float(band_cost[cost == 0.0].sum())
    assert graded > 0  # the cost rises before the band
