"""Training-only reward shaping: a penalty on changing the action from one control period to the next.

Why (``docs/notes/2026-12-02-ppo-v0-tuning.md``): the averaged model the policy trains on takes a new fin
pattern at no cost (its transitional half-strokes are off in the envs, ``EnvConfig.transitions``), while the
full model, like the robot, pays a transitional stroke at every change. As PPO trains on, its policies switch
patterns more often, and their success on the full model falls while it still rises on the averaged one. The
penalty prices that switching while training; the environments, their rewards and the evaluations are
unchanged.

The penalty of env ``i`` at step ``t`` is ``weight * mean_j |a_t[i, j] - a_{t-1}[i, j]|`` over the action's
components (the actions SB3 sends, in the action space's units); the first step of every episode has none.
It is set by ``action_change_penalty`` in the hyperparameter file's ``pectoral_gym.agents.training.train`` section
(:mod:`pectoral_gym.agents.training.zoo_format`; 0: off). rl-baselines3-zoo does not read that section, so it trains
without it.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

__all__ = ["INFO_KEY", "ActionChangePenalty"]

INFO_KEY = "reward_action_change"  # the penalty of the step (<= 0), in each env's info


class ActionChangePenalty(VecEnvWrapper):
    """Subtract ``weight * mean |a_t - a_{t-1}|`` from every env's reward (see the module docstring).

    Args:
        venv: The SB3 vector env (same-step autoreset, as SB3's).
        weight: Penalty per unit of mean absolute action change (>= 0, finite).

    Raises:
        ValueError: If ``weight`` is negative or not finite.
    """

    def __init__(self, venv: VecEnv, weight: float):
        weight = float(weight)
        if not np.isfinite(weight) or weight < 0:
            raise ValueError(f"action_change_penalty must be a finite number >= 0, got {weight!r}")
        super().__init__(venv)
        self.weight = weight
        shape = (self.num_envs, int(np.prod(self.action_space.shape)))
        self.previous = np.zeros(shape, dtype=np.float64)
        self.has_previous = np.zeros(self.num_envs, dtype=bool)
        self.actions = np.zeros(shape, dtype=np.float64)

    def reset(self) -> VecEnvObs:
        """Reset every env; the next step has no penalty."""
        self.has_previous[:] = False
        return self.venv.reset()

    def step_async(self, actions: np.ndarray) -> None:
        """Remember the actions and send them on."""
        self.actions = np.asarray(actions, dtype=np.float64).reshape(self.previous.shape).copy()
        self.venv.step_async(actions)

    def step_wait(self) -> VecEnvStepReturn:
        """The wrapped step with the penalty added to each reward and written to ``info[INFO_KEY]``."""
        obs, rewards, dones, infos = self.venv.step_wait()
        change = np.abs(self.actions - self.previous).mean(axis=1)
        penalty = np.where(self.has_previous, -self.weight * change, 0.0)
        rewards = np.asarray(rewards)
        rewards = (rewards + penalty).astype(rewards.dtype)
        for info, value in zip(infos, penalty, strict=True):
            info[INFO_KEY] = float(value)
        self.previous = self.actions
        self.has_previous = ~np.asarray(dones, dtype=bool)  # a new episode starts after done: no penalty
        return obs, rewards, dones, infos
