"""The action a trained Gaussian policy deploys: the mean of its clipped Gaussian, ``E[clip(a, low, high)]``.

A Stable-Baselines3 policy with a diagonal Gaussian (PPO, A2C on a ``Box`` action space) trains on samples
``a ~ N(mu(obs), sigma^2)`` that the env clips to the action bounds. SB3's deterministic action is
``clip(mu, low, high)``: where the mean lies beyond a bound by more than the spread, it sits at the bound,
while the stochastic policy the training saw still moved away from it now and then. Deploying
``E[clip(a, low, high)]`` per action dimension keeps the stochastic policy's average command instead; it
tends to ``clip(mu, low, high)`` as ``sigma -> 0`` and stays inside ``[low, high]``.

Closed form, for ``X ~ N(mu, sigma^2)``, ``alpha = (low - mu) / sigma``, ``beta = (high - mu) / sigma``,
``Phi`` and ``phi`` the standard normal cdf and pdf::

    E[clip(X, low, high)] = low Phi(alpha) + high (1 - Phi(beta)) + mu (Phi(beta) - Phi(alpha))
                            + sigma (phi(alpha) - phi(beta))

Policies of other distributions (squashed Gaussians of SAC, gSDE, categorical) and deterministic actors (TD3,
DDPG) have no such choice here: :func:`expected_clipped_action` returns ``None`` for them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.special import ndtr

__all__ = ["clipped_gaussian_mean", "diag_gaussian_policy", "expected_clipped_action"]

_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)


def clipped_gaussian_mean(mean: np.ndarray, std: np.ndarray, low: np.ndarray | float = -1.0,
                          high: np.ndarray | float = 1.0) -> np.ndarray:
    """``E[clip(X, low, high)]`` for ``X ~ N(mean, std^2)``, elementwise (the closed form in the module docstring).

    Args:
        mean: Gaussian means (any shape; action units).
        std: Standard deviations, ``>= 0``, broadcastable to ``mean``; where 0 the result is ``clip(mean)``.
        low: Lower clip bounds, broadcastable to ``mean``.
        high: Upper clip bounds, ``> low``, broadcastable to ``mean``.

    Returns:
        float64 array of the broadcast shape, each entry in ``[low, high]``.

    Raises:
        ValueError: If a standard deviation is negative or not finite, or a bound pair has ``low >= high``.
    """
    mean, std = np.asarray(mean, dtype=np.float64), np.asarray(std, dtype=np.float64)
    low, high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    if not np.all(np.isfinite(std)) or np.any(std < 0):
        raise ValueError("standard deviations must be finite and >= 0")
    if np.any(low >= high):
        raise ValueError("clip bounds must have low < high")
    mean, std, low, high = np.broadcast_arrays(mean, std, low, high)
    positive = std > 0
    s = np.where(positive, std, 1.0)  # placeholder where std == 0 (those entries take clip(mean) below)
    alpha, beta = (low - mean) / s, (high - mean) / s
    cdf_alpha, cdf_beta = ndtr(alpha), ndtr(beta)
    pdf_alpha, pdf_beta = _INV_SQRT_2PI * np.exp(-0.5 * alpha**2), _INV_SQRT_2PI * np.exp(-0.5 * beta**2)
    value = (low * cdf_alpha + high * ndtr(-beta) + mean * (cdf_beta - cdf_alpha)
             + s * (pdf_alpha - pdf_beta))
    # rounding can step a hair outside the bounds when the mass sits at one of them
    return np.clip(np.where(positive, value, mean), low, high)


def diag_gaussian_policy(model: Any) -> bool:
    """Whether an SB3 model acts through an unsquashed diagonal Gaussian on a ``Box`` action space.

    True for PPO and A2C with their default ``MlpPolicy`` on the fish envs; false for SAC (squashed Gaussian),
    TD3 and DDPG (deterministic actors), gSDE policies and discrete action spaces.
    """
    from gymnasium import spaces
    from stable_baselines3.common.distributions import DiagGaussianDistribution

    policy = getattr(model, "policy", None)
    # exact type: SquashedDiagGaussianDistribution subclasses DiagGaussianDistribution
    return (type(getattr(policy, "action_dist", None)) is DiagGaussianDistribution
            and not getattr(policy, "squash_output", False) and hasattr(policy, "get_distribution")
            and isinstance(getattr(policy, "action_space", None), spaces.Box))


def expected_clipped_action(model: Any, obs: np.ndarray) -> np.ndarray | None:
    """``E[clip(a, low, high)]`` of an SB3 diagonal-Gaussian policy at a batch of (normalised) observations.

    Args:
        model: The SB3 model (``BaseAlgorithm``).
        obs: Observations ``(n, obs_size)``, already normalised as the policy was trained.

    Returns:
        Actions ``(n, action_size)`` float64 within the action space's bounds, or ``None`` if the model is not
        a diagonal-Gaussian policy (:func:`diag_gaussian_policy`): the caller then uses SB3's own action.
    """
    if not diag_gaussian_policy(model):
        return None
    import torch as th

    policy = model.policy
    policy.set_training_mode(False)  # as SB3's predict does (dropout, batch norm)
    obs_tensor, _ = policy.obs_to_tensor(obs)
    with th.no_grad():
        normal = policy.get_distribution(obs_tensor).distribution
        mean, std = normal.mean.cpu().numpy(), normal.stddev.cpu().numpy()
    space = policy.action_space
    mean = mean.reshape((-1, *space.shape))
    std = np.broadcast_to(std.reshape((-1, *space.shape)), mean.shape)
    return clipped_gaussian_mean(mean, std, space.low, space.high)
