"""load_policy builds no optimizer: the same actions as SB3's own load, the saved state kept, no training."""

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.save_util import load_from_zip_file

from pectoral_gym.agents.training.policy import load_policy


def _trained(algo, tmp_path, **kwargs):
    """A model of ``algo`` after a few updates on Pendulum (so that its optimizer holds a state), saved to a zip."""
    model = algo("MlpPolicy", gym.make("Pendulum-v1"), seed=3, device="cpu", **kwargs)
    model.learn(64)
    path = tmp_path / f"{algo.__name__.lower()}.zip"
    model.save(path)
    return path


@pytest.mark.parametrize(("algo", "kwargs"), [(PPO, {"n_steps": 32, "batch_size": 16, "n_epochs": 1}),
                                              (SAC, {"learning_starts": 16, "batch_size": 16})])
def test_acts_and_saves_as_sb3_loads_it(algo, kwargs, tmp_path):
    path = _trained(algo, tmp_path, **kwargs)
    controller, reference = load_policy(path), algo.load(path, device="cpu")
    assert controller.name == algo.__name__.lower()
    obs = np.random.default_rng(5).normal(size=(32, 3)).astype(np.float32)
    expected = np.clip(reference.predict(obs, deterministic=True)[0], -1.0, 1.0)
    np.testing.assert_array_equal(controller.act_batch(obs), expected)  # bit for bit
    for ours, theirs in zip(controller.model.policy.parameters(), reference.policy.parameters(), strict=True):
        assert torch.equal(ours, theirs)
    # what a save records: the saved policy settings, and the optimizer's state as it was loaded
    assert controller.model.policy_kwargs == reference.policy_kwargs
    assert controller.model.policy._get_constructor_parameters() == reference.policy._get_constructor_parameters()
    controller.model.save(tmp_path / "again.zip")
    saved, resaved = load_from_zip_file(path)[1], load_from_zip_file(tmp_path / "again.zip")[1]
    assert saved.keys() == resaved.keys() and any("optimizer" in name for name in saved)
    for name, state in saved.items():  # the networks' and the optimizers' state dicts
        _assert_same(state, resaved[name])


def _assert_same(a, b):
    """Equal nested state dicts (tensors equal bit for bit)."""
    if isinstance(a, torch.Tensor):
        assert isinstance(b, torch.Tensor) and torch.equal(a, b)
    elif isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys()
        for key in a:
            _assert_same(a[key], b[key])
    elif isinstance(a, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _assert_same(x, y)
    else:
        assert a == b

def test_cannot_train(tmp_path):
    controller = load_policy(_trained(PPO, tmp_path, n_steps=32, batch_size=16, n_epochs=1))
    with pytest.raises(RuntimeError, match="to act only"):
        controller.model.policy.optimizer.zero_grad()
    with pytest.raises(RuntimeError, match="to act only"):
        controller.model.policy.optimizer.step()


def test_does_not_import_torch_compiler(tmp_path):
    """Building a torch optimizer imports torch._dynamo (most of a second in each deploy worker): none is built."""
    path = _trained(PPO, tmp_path, n_steps=32, batch_size=16, n_epochs=1)
    code = ("import sys; from pectoral_gym.agents.training.policy import load_policy; "
            f"load_policy({str(path)!r}).act(__import__('numpy').zeros(3)); print('torch._dynamo' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split()[-1] == "False"
