"""Native vector environment: ``num_envs`` fish on one batched model."""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from pectoral_gym.envs.core import EnvConfig, EnvCore, env_signature
from pectoral_gym.envs.layout import ACTION_SIZE, O_REWARD, O_TERMINATED
from pectoral_gym.envs.observation import OBS_X, OBS_Y, observation_bounds, observation_structure
from pectoral_gym.registration import MAX_EPISODE_STEPS
from pectoral_gym.versions import LATEST

__all__ = ["PectoralFishVectorEnv"]


class PectoralFishVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`~pectoral_gym.envs.fish_env.PectoralFishEnv` stepped as one batch.

    One batched model of ``num_envs`` fish and the task kernels of
    :mod:`pectoral_gym.envs.tasks.kernels` advance all environments in a few compiled
    calls (threads for 64 envs and more). Env ``i`` behaves exactly like
    ``gym.make(id)`` reset with ``seed + i`` (as ``SyncVectorEnv`` seeds it)
    and given the same actions, step for step, including the autoreset.

    Autoreset (``autoreset_mode``, published in ``metadata["autoreset_mode"]`` as
    Gymnasium 1.x vector envs do; see https://farama.org/Vector-Autoreset-Mode):

    * ``NEXT_STEP`` (default): the step after an env terminated or was truncated
      resets it: its action is ignored (not even checked), it returns the new
      episode's first observation, reward 0, ``terminated = truncated = False``
      and the reset's ``info`` values.
    * ``SAME_STEP``: an env that ends is reset in the same step: its observation
      is the new episode's first one, ``info["final_obs"]`` (object array) and
      ``info["final_info"]`` (dict of arrays) hold the last observation and
      ``info`` of the old one, masked by ``info["_final_obs"]``,
      ``info["_final_info"]``; the top-level ``info`` values are the reset's.
    * ``DISABLED``: no autoreset; reset finished envs with
      ``reset(options={"reset_mask": mask})`` before the next step (stepping a
      finished env raises ``ValueError``).

    ``info`` holds one array per key of the single env's ``info`` (reward
    terms, ``"distance"``, ``"is_success"`` or ``"tracking_error"``: the task
    table's ``Task.info_fields``, :class:`pectoral_gym.envs.tasks.row.Task`), each with
    its boolean mask ``"_<key>"``, from ``reset()`` as from ``step()``: the
    same as ``SyncVectorEnv`` of single envs gives.

    Args:
        num_envs: Number of environments.
        max_episode_steps: Truncation after this many steps (240 as registered).
        render_mode: ``None`` or ``"rgb_array"``: :meth:`render` returns one frame per env, as Gymnasium's
            ``SyncVectorEnv`` does (``gymnasium.wrappers.vector.HumanRendering`` shows them tiled in a window).
        autoreset_mode: ``AutoresetMode`` or its value (``"NextStep"``, ``"SameStep"``, ``"Disabled"``).
        **kwargs: The settings of :class:`~pectoral_gym.envs.fish_env.PectoralFishEnv`
            (the fields of :class:`~pectoral_gym.envs.core.EnvConfig`, ``model`` among them).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 2, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, *, max_episode_steps: int = MAX_EPISODE_STEPS,
                 render_mode: str | None = None, autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 **kwargs: Any):
        if int(num_envs) < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        if max_episode_steps is None or int(max_episode_steps) < 1:
            raise ValueError(f"max_episode_steps must be an integer >= 1, got {max_episode_steps}")
        if render_mode is not None and render_mode not in type(self).metadata["render_modes"]:
            raise ValueError(f"render_mode must be 'rgb_array' or None, got {render_mode!r} (for a window, wrap the "
                             "env in gymnasium.wrappers.vector.HumanRendering)")
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ValueError(f"autoreset_mode must be one of {[m.value for m in AutoresetMode]}, "
                             f"got {autoreset_mode!r}") from None
        self.num_envs = int(num_envs)
        self.max_episode_steps = int(max_episode_steps)
        self.render_mode = render_mode
        self.config = EnvConfig.recommended(**kwargs)  # the latest version's settings, then the arguments
        # one frame per control period, as the single env
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode,
                         "render_fps": 1.0 / self.config.control_period}
        self.core = EnvCore(self.num_envs, self.config)
        self.single_action_space = spaces.Box(-1.0, 1.0, (ACTION_SIZE,), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        low, high = observation_bounds(self.config.control_period, self.config.ref_speed,
                                       self.config.observe_fins)
        self.single_observation_space = spaces.Box(low, high, dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.observation_structure = observation_structure(self.config.observe_fins)
        self._rngs: list[np.random.Generator | None] = [None] * self.num_envs
        self.steps = np.zeros(self.num_envs, dtype=np.int64)
        self.prev_done = np.zeros(self.num_envs, dtype=np.bool_)
        self._info_fields = self.core.task_state.info_fields  # the task table's info entries (and cost), in order
        self._all = np.ones(self.num_envs, dtype=np.bool_)
        self._renderer = None
        #: With a render mode: each env's path [m] since its episode began, as the single env's ``trail``.
        self.trails: list[list[tuple[float, float]]] = [[] for _ in range(self.num_envs)]

    def _infos(self, mask: np.ndarray) -> dict[str, Any]:
        """``info`` of the envs in ``mask`` from ``core.out`` (zero for the others, as ``SyncVectorEnv``)."""
        out = self.core.out
        everyone = bool(mask.all())
        info: dict[str, Any] = {}
        for name, k, flag in self._info_fields:
            if flag:
                info[name] = (out[:, k] > 0.5) & mask
            else:
                info[name] = out[:, k].copy() if everyone else np.where(mask, out[:, k], 0.0)
            info["_" + name] = mask.copy()
        return info

    @property
    def last_observations(self) -> np.ndarray:
        """The observations ``(num_envs, 19)`` after the last ``reset`` or ``step`` (a copy)."""
        return self.core.obs.copy()

    @property
    def fin_patterns(self) -> np.ndarray:
        """Commanded fin patterns ``(num_envs, 2, 4)``: ``(bias, amplitude, period, ratio)``, right fin first."""
        return self.core.beats.copy()

    @property
    def env_rngs(self) -> list[np.random.Generator | None]:
        """The random generator of each env (env ``i`` draws only from its own)."""
        return self._rngs

    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None):
        """Reset all envs (or those in ``options["reset_mask"]``); env ``i`` is seeded with ``seed + i``.

        Args:
            seed: ``None`` (keep each env's generator, or seed it from entropy on first use),
                an int (env ``i`` gets ``seed + i``) or one seed per env.
            options: ``{"reset_mask": bool array}`` resets only the masked envs.

        Returns:
            ``(observations (num_envs, 19), info)``, ``info`` with the step's keys (zero reward
            terms, the real distance), masked by the reset envs.
        """
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(self.num_envs)]
            super().reset(seed=int(seed))
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"got {len(seeds)} seeds for {self.num_envs} envs")
        unknown = sorted(set(options or ()) - {"reset_mask"})
        if unknown:  # e.g. the single env's "start" and "goal": silently ignoring them would mislead
            raise ValueError(f"reset options: unknown keys {unknown}; the vector env takes 'reset_mask' (pin a start "
                             "or goal with the single env's reset options)")
        mask = np.ones(self.num_envs, dtype=np.bool_)
        if options and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"], dtype=np.bool_)
            if mask.shape != (self.num_envs,):
                raise ValueError(f"reset_mask must have shape ({self.num_envs},), got {mask.shape}")
        index = np.flatnonzero(mask)
        for i in index:
            if seeds[i] is not None or self._rngs[i] is None:
                self._rngs[i], _ = seeding.np_random(seeds[i])
        self.core.reset(index, self._rngs)
        self.steps[index] = 0
        self.prev_done[index] = False
        self._trace(mask)
        return self.core.obs.copy(), self._infos(mask)

    def step(self, actions: np.ndarray):
        """Step every env one control period, with the autoreset of ``autoreset_mode`` (class docstring).

        Returns:
            ``(observations, rewards, terminations, truncations, infos)`` as arrays over envs.

        Raises:
            ValueError: If ``actions`` does not have shape ``(num_envs, 8)``, an action (of an env
                that is not being reset) is not finite, or (``DISABLED``) a finished env was not reset.
        """
        actions = np.asarray(actions)
        if actions.shape != (self.num_envs, ACTION_SIZE):
            raise ValueError(f"actions must have shape ({self.num_envs}, {ACTION_SIZE}), got {actions.shape}")
        if actions.dtype != np.float32 and actions.dtype != np.float64:
            actions = actions.astype(np.float64)
        core = self.core
        mode = self.autoreset_mode
        resetting = self.prev_done
        if mode is AutoresetMode.DISABLED and resetting.any():
            raise ValueError(f"envs {np.flatnonzero(resetting).tolist()} have ended; with autoreset_mode DISABLED "
                             "reset them (reset(options={'reset_mask': mask})) before the next step")
        if mode is AutoresetMode.NEXT_STEP:
            core.step(actions, resetting)
        else:
            core.step(actions)
        self.steps += 1
        started = resetting.copy() if mode is AutoresetMode.NEXT_STEP else None  # envs whose episode starts anew
        if mode is AutoresetMode.NEXT_STEP and resetting.any():
            index = np.flatnonzero(resetting)
            core.reset(index, self._rngs)
            self.steps[index] = 0
        out = core.out
        terminated = out[:, O_TERMINATED] > 0.5
        truncated = self.steps >= self.max_episode_steps
        rewards = out[:, O_REWARD].copy()
        done = terminated | truncated
        if mode is AutoresetMode.SAME_STEP:
            if done.any():
                final_info = self._infos(done)
                final_obs = np.full(self.num_envs, None, dtype=object)
                index = np.flatnonzero(done)
                for i in index:
                    final_obs[i] = core.obs[i].copy()
                core.reset(index, self._rngs)
                self.steps[index] = 0
                started = done
                info = self._infos(self._all)
                info.update(final_obs=final_obs, _final_obs=done.copy(), final_info=final_info,
                            _final_info=done.copy())
            else:
                info = self._infos(self._all)
        else:
            info = self._infos(self._all)
            self.prev_done = done
        self._trace(started)
        return core.obs.copy(), rewards, terminated, truncated, info

    def _trace(self, started: np.ndarray | None) -> None:
        """With a render mode: add each env's position to its trail, which restarts for the envs in ``started``."""
        if self.render_mode is None:
            return
        obs = self.core.obs
        for i in range(self.num_envs):
            point = (float(obs[i, OBS_X]), float(obs[i, OBS_Y]))
            if started is not None and started[i]:
                self.trails[i] = [point]
            else:
                self.trails[i].append(point)

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One ``(H, W, 3)`` uint8 top view per env (``rgb_array``), as ``SyncVectorEnv.render`` returns them.

        Each frame is the single env's (:class:`~pectoral_gym.envs.fish_env.PectoralFishEnv`): the tank, the
        target, the fish and its trail. Without a render mode: a warning and ``None``, as the single env.
        """
        if self.render_mode is None:
            spec = getattr(self, "spec", None)
            env_id = spec.id if spec is not None else LATEST[self.config.model]
            from pectoral_gym.envs.rendering import warn_no_render_mode

            warn_no_render_mode(env_id, "gym.make_vec")
            return None
        if self._renderer is None:
            from pectoral_gym.envs.rendering import FishRenderer

            self._renderer = FishRenderer(self.render_mode, self.metadata["render_fps"])
        return tuple(self._renderer.render(self.core, i, self.trails[i], self.config) for i in range(self.num_envs))

    def close_extras(self, **kwargs: Any) -> None:
        """Release the renderer (pygame's surface), if one was made."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


_P = inspect.Parameter
PectoralFishVectorEnv.__init__.__signature__ = env_signature(
    _P("num_envs", _P.POSITIONAL_OR_KEYWORD, default=1, annotation="int"),
    _P("max_episode_steps", _P.KEYWORD_ONLY, default=MAX_EPISODE_STEPS, annotation="int"),
    _P("render_mode", _P.KEYWORD_ONLY, default=None, annotation="str | None"),
    _P("autoreset_mode", _P.KEYWORD_ONLY, default=AutoresetMode.NEXT_STEP, annotation="AutoresetMode | str"))
