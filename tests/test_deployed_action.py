"""The deployed action of Gaussian policies, E[clip(a)]: closed form against quadrature and sampling, the limits,
and which SB3 policies get it."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from scipy import integrate

from pectoral_gym.agents.training.deployed_action import (
    clipped_gaussian_mean,
    diag_gaussian_policy,
    expected_clipped_action,
)
from pectoral_gym.agents.training.policy import SB3Controller

CASES = [  # mean, std, low, high
    (0.0, 1.0, -1.0, 1.0), (-1.3, 0.6, -1.0, 1.0), (1.7, 0.5, -1.0, 1.0), (0.4, 0.05, -1.0, 1.0),
    (-3.0, 2.0, -1.0, 1.0), (0.0, 10.0, -1.0, 1.0), (2.5, 0.8, -2.0, 2.0), (0.1, 0.3, 0.0, 0.5),
]


def quadrature(mean, std, low, high):
    """E[clip(X, low, high)] by numerical integration of the normal density over the three pieces."""
    pdf = lambda x: np.exp(-0.5 * ((x - mean) / std) ** 2) / (std * np.sqrt(2 * np.pi))  # noqa: E731
    below = integrate.quad(pdf, -np.inf, low, epsabs=1e-13)[0]
    above = integrate.quad(pdf, high, np.inf, epsabs=1e-13)[0]
    inside = integrate.quad(lambda x: x * pdf(x), low, high, epsabs=1e-13, points=[mean] if low < mean < high
                            else None)[0]
    return low * below + inside + high * above


@pytest.mark.parametrize(("mean", "std", "low", "high"), CASES)
def test_closed_form_matches_quadrature(mean, std, low, high):
    assert clipped_gaussian_mean(mean, std, low, high) == pytest.approx(quadrature(mean, std, low, high), abs=1e-9)


def test_closed_form_matches_sampling():
    rng = np.random.default_rng(7)
    mean, std = np.array([-1.3, 0.0, 0.9, 2.0]), np.array([0.6, 1.0, 0.3, 1.5])
    samples = np.clip(rng.normal(mean, std, size=(400_000, 4)), -1.0, 1.0)
    tolerance = 5 * samples.std(axis=0) / np.sqrt(len(samples))  # five standard errors of the sample mean
    assert np.all(np.abs(samples.mean(axis=0) - clipped_gaussian_mean(mean, std)) < tolerance)


def test_small_spread_tends_to_the_clipped_mean():
    mean = np.array([-2.0, -1.0, -0.999, -0.3, 0.0, 0.7, 1.0, 1.5])
    np.testing.assert_array_equal(clipped_gaussian_mean(mean, np.zeros(8)), np.clip(mean, -1, 1))
    for std in (1e-1, 1e-3, 1e-6, 1e-9):
        # clip is 1-Lipschitz: |E[clip(X)] - clip(mean)| <= E|X - mean| = std sqrt(2 / pi)
        gap = np.abs(clipped_gaussian_mean(mean, np.full(8, std)) - np.clip(mean, -1, 1))
        assert np.all(gap <= std * np.sqrt(2 / np.pi) + 1e-15)


def test_limits_symmetry_and_bounds():
    assert clipped_gaussian_mean(0.0, 3.0) == pytest.approx(0.0, abs=1e-15)  # symmetric about 0
    assert clipped_gaussian_mean(-0.6, 0.8) == pytest.approx(-clipped_gaussian_mean(0.6, 0.8), abs=1e-15)
    assert clipped_gaussian_mean(-12.0, 0.5) == -1.0 and clipped_gaussian_mean(12.0, 0.5) == 1.0
    # a huge spread puts half the mass on each bound
    assert clipped_gaussian_mean(0.3, 1e6) == pytest.approx(0.0, abs=1e-5)
    values = clipped_gaussian_mean(np.linspace(-5, 5, 101), np.linspace(0, 4, 101))
    assert np.all(values >= -1) and np.all(values <= 1) and np.all(np.diff(values) >= 0)
    with pytest.raises(ValueError, match="standard deviations"):
        clipped_gaussian_mean(0.0, -0.1)
    with pytest.raises(ValueError, match="low < high"):
        clipped_gaussian_mean(0.0, 1.0, 1.0, 1.0)


class Box8(gym.Env):
    """A stand-in env with the fish's action space, [-1, 1]^8, for building untrained SB3 models."""

    observation_space = gym.spaces.Box(-10.0, 10.0, (5,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (8,), np.float32)

    def reset(self, seed=None, options=None):
        return np.zeros(5, np.float32), {}

    def step(self, action):
        return np.zeros(5, np.float32), 0.0, True, False, {}


def _ppo(env, **kwargs):
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", env, n_steps=64, batch_size=64, seed=0, device="cpu", **kwargs)
    with torch.no_grad():  # a mean beyond the bounds on some entries, a spread like the demo policy's
        model.policy.action_net.bias.copy_(torch.linspace(-2.5, 2.5, model.policy.action_net.bias.numel()))
        if hasattr(model.policy, "log_std") and model.policy.log_std.numel() > 1:
            model.policy.log_std.fill_(np.log(0.6))
    return model


def test_ppo_policy_deploys_the_mean_of_its_clipped_samples():
    model = _ppo(Box8())
    controller = SB3Controller(model, expected_clip=True)
    assert controller.expected_clip and diag_gaussian_policy(model) and not SB3Controller(model).expected_clip
    obs = np.random.default_rng(3).normal(size=(3, 5)).astype(np.float32)
    actions = controller.act_batch(obs)
    assert actions.shape == (3, 8) and actions.dtype == np.float32
    torch.manual_seed(0)  # SB3's own stochastic actions, clipped by its predict as in training's env steps
    n = 100_000
    samples, _ = model.predict(np.repeat(obs[:1], n, axis=0), deterministic=False)
    tolerance = 5 * samples.std(axis=0) / np.sqrt(n) + 1e-6  # float32 actions
    assert np.all(np.abs(samples.mean(axis=0) - actions[0]) < tolerance)
    # without the option, or with no spread left, SB3's deterministic action clip(mean)
    deterministic, _ = model.predict(obs, deterministic=True)
    np.testing.assert_array_equal(SB3Controller(model).act_batch(obs), np.clip(deterministic, -1, 1))
    with torch.no_grad():
        model.policy.log_std.fill_(-30.0)
    np.testing.assert_allclose(controller.act_batch(obs), deterministic, atol=1e-6)


def test_other_bounds_follow_the_action_space():
    model = _ppo(gym.make("Pendulum-v1"))  # a Box of [-2, 2]
    obs = np.array([[1.0, 0.0, 0.0]], np.float32)
    with torch.no_grad():
        model.policy.action_net.bias.fill_(2.5)
    normal = model.policy.get_distribution(model.policy.obs_to_tensor(obs)[0]).distribution
    mean, std = normal.mean.detach().numpy(), normal.stddev.detach().numpy()
    expected = quadrature(float(mean[0, 0]), float(std[0, 0]), -2.0, 2.0)
    assert expected_clipped_action(model, obs)[0, 0] == pytest.approx(expected, abs=1e-6)


def test_policies_without_a_diagonal_gaussian_keep_sb3s_action():
    from stable_baselines3 import PPO, SAC, TD3

    obs = np.random.default_rng(4).normal(size=(2, 5)).astype(np.float32)
    for model in (SAC("MlpPolicy", Box8(), seed=0, device="cpu"), TD3("MlpPolicy", Box8(), seed=0, device="cpu"),
                  PPO("MlpPolicy", Box8(), n_steps=64, batch_size=64, use_sde=True, seed=0, device="cpu")):
        controller = SB3Controller(model, expected_clip=True)
        assert not controller.expected_clip and expected_clipped_action(model, obs) is None
        np.testing.assert_array_equal(controller.act_batch(obs), model.predict(obs, deterministic=True)[0])
    sac = SB3Controller(SAC("MlpPolicy", Box8(), seed=0, device="cpu"))
    sac.expected_clip = True  # set after loading: still SB3's action
    np.testing.assert_array_equal(sac.act_batch(obs), sac.model.predict(obs, deterministic=True)[0])
    categorical = PPO("MlpPolicy", "CartPole-v1", n_steps=64, batch_size=64, seed=0, device="cpu")
    assert not diag_gaussian_policy(categorical)
