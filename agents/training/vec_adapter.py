"""Stable-Baselines3 ``VecEnv`` over the native batched :class:`~pectoral_gym.envs.PectoralFishVectorEnv`.

SB3 steps ``n`` environments through one ``VecEnv``; :class:`FishVecEnv` feeds
it from one batched fish model instead of ``n`` environment copies.

Autoreset: SB3 expects the reset in the *same* step: ``done[i]`` is True,
``obs[i]`` is already the first observation of the new episode and
``infos[i]["terminal_observation"]`` holds the last observation of the old
one. That is the vector env's ``AutoresetMode.SAME_STEP`` (its
``info["final_obs"]`` becomes ``terminal_observation``, its
``info["final_info"]`` the finished env's ``info``); each env keeps drawing
from its own generator, exactly as ``DummyVecEnv`` of single envs seeded
``seed + i``. ``infos[i]["TimeLimit.truncated"]`` is True when the episode
hit the step limit without terminating, as SB3 uses it for bootstrapping.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvStepReturn

__all__ = ["FishVecEnv", "env_arguments", "make_fish_vec_env"]


class FishVecEnv(VecEnv):
    """SB3 ``VecEnv`` adapter around a :class:`~pectoral_gym.envs.PectoralFishVectorEnv` (same-step autoreset).

    Args:
        vector_env: The native vector env, made with ``autoreset_mode=AutoresetMode.SAME_STEP``.

    Attributes:
        vector_env: The wrapped native vector env.
    """

    def __init__(self, vector_env: Any):
        from pectoral_gym.envs import PectoralFishVectorEnv

        if not isinstance(vector_env, PectoralFishVectorEnv):
            raise TypeError(f"FishVecEnv wraps a PectoralFishVectorEnv, got {type(vector_env).__name__}")
        if vector_env.autoreset_mode is not AutoresetMode.SAME_STEP:
            raise ValueError("FishVecEnv needs a PectoralFishVectorEnv made with "
                             f"autoreset_mode=AutoresetMode.SAME_STEP (SB3 resets in the same step), "
                             f"got {vector_env.autoreset_mode}")
        self.vector_env = vector_env
        super().__init__(vector_env.num_envs, vector_env.single_observation_space, vector_env.single_action_space)
        self._actions: np.ndarray | None = None
        self._info_keys: tuple[str, ...] = ()

    @property
    def config(self):
        """The :class:`~pectoral_gym.envs.core.EnvConfig` of the environments."""
        return self.vector_env.config

    def reset(self) -> np.ndarray:
        """Reset every env (with the seeds of :meth:`seed`, used once); returns ``(num_envs, 19)`` observations."""
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        options = self._options[0] if self._options and self._options[0] else None
        obs, _ = self.vector_env.reset(seed=seeds, options=options)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        """Store the actions ``(num_envs, 8)`` for :meth:`step_wait`."""
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        """Step every env; finished envs are reset in the same step (see the module docstring).

        Returns:
            ``(obs (n, 19), rewards (n,) float32, dones (n,) bool, infos)``, one ``info`` dict per env.
        """
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        actions = self._actions
        if actions.ndim == 1 and self.num_envs == 1:
            actions = actions[None]
        obs, rewards, terminated, truncated, info = self.vector_env.step(actions)
        self._actions = None
        dones = terminated | truncated
        time_limit = truncated & ~terminated
        infos = _rows(info, time_limit)
        if dones.any():  # the finished envs' own info, and their last observation
            finished = np.flatnonzero(dones)
            final_obs = info["final_obs"]
            for i, row in zip(finished, _rows(info["final_info"], time_limit, finished), strict=True):
                row["terminal_observation"] = final_obs[i]
                row["TimeLimit.truncated"] = row.pop("TimeLimit.truncated")  # last, as in every other row
                infos[i] = row
        return obs, rewards.astype(np.float32), dones, infos

    def close(self) -> None:
        """Close the vector env."""
        self.vector_env.close()

    def _indices(self, indices: VecEnvIndices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, (int, np.integer)):
            return [int(indices)]
        return list(indices) if isinstance(indices, Iterable) else [indices]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The vector env's attribute, once per requested env (the envs share one object)."""
        if attr_name == "render_mode":
            return [None] * len(self._indices(indices))
        value = getattr(self.vector_env, attr_name)
        return [value] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set an attribute of the vector env (shared by all envs, so only all at once)."""
        if len(self._indices(indices)) != self.num_envs:
            raise NotImplementedError("the envs share one vector env; set attributes for all of them at once")
        setattr(self.vector_env, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        """Call a method of the vector env once and return its result for each requested env."""
        result = getattr(self.vector_env, method_name)(*method_args, **method_kwargs)
        return [result] * len(self._indices(indices))

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        """No Gymnasium wrappers here (episode statistics come from ``VecMonitor``)."""
        return [False] * len(self._indices(indices))

    def get_images(self) -> Sequence[np.ndarray | None]:
        """The native vector env does not render."""
        return [None] * self.num_envs


def _rows(info: dict[str, Any], time_limit: np.ndarray, envs: np.ndarray | None = None) -> list[dict[str, Any]]:
    """One dict per env (of ``envs``, default all) of the array entries of a vector ``info``.

    Masks and nested entries are dropped; each dict ends with ``"TimeLimit.truncated"`` from ``time_limit``
    (``(num_envs,)`` bool). Built column-wise, as lists: this runs once per step of every env (SB3 wants a dict each).
    """
    keys = [k for k, v in info.items() if not k.startswith("_") and isinstance(v, np.ndarray) and v.dtype != object]
    keys.append("TimeLimit.truncated")
    columns = [info[k] for k in keys[:-1]] + [time_limit]
    if envs is not None:
        columns = [column[envs] for column in columns]
    return [dict(zip(keys, row, strict=True)) for row in zip(*(column.tolist() for column in columns), strict=True)]


def env_arguments(env_kwargs: dict[str, Any] | None) -> dict[str, Any]:
    """Environment arguments from a JSON/YAML-ready dict: ``params`` may be a dict of ``FishParams`` fields.

    Raises:
        ValueError: If ``model`` is given (the env id fixes it) or ``params`` names unknown fields.
    """
    from pectoral_gym.model.params import FishParams

    kwargs = dict(env_kwargs or {})
    if "model" in kwargs:
        raise ValueError("env_kwargs must not set 'model'; it is fixed by the env id")
    if isinstance(kwargs.get("params"), dict):
        try:
            kwargs["params"] = FishParams(**kwargs["params"])
        except TypeError as error:
            raise ValueError(f"env_kwargs['params']: {error}") from None
    return kwargs


def make_fish_vec_env(env_id: str, n_envs: int, env_kwargs: dict[str, Any] | None = None, seed: int | None = None,
                      max_episode_steps: int | None = None) -> FishVecEnv:
    """A :class:`FishVecEnv` of ``n_envs`` fish of a registered id; env ``i`` gets seed ``seed + i`` at the first reset.

    Args:
        env_id: A registered fish env id (:data:`pectoral_gym.versions.ENV_VERSIONS`).
        n_envs: Number of environments.
        env_kwargs: Environment arguments (``task``, ``randomize``, reward weights, ``params`` as a dict, ...).
        seed: Seed of the first reset (``None``: from entropy).
        max_episode_steps: Truncation (default: as registered).
    """
    from pectoral_gym.envs import PectoralFishVectorEnv
    from pectoral_gym.registration import registered_settings

    kwargs = registered_settings(env_id, env_arguments(env_kwargs))
    if max_episode_steps is not None:
        kwargs["max_episode_steps"] = max_episode_steps
    venv = FishVecEnv(PectoralFishVectorEnv(num_envs=n_envs, autoreset_mode=AutoresetMode.SAME_STEP, **kwargs))
    if seed is not None:
        venv.seed(seed)
    return venv
