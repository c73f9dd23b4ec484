"""The batched environment core shared by the single and the vector environment.

:class:`EnvCore` holds one batched fish model of ``n`` fish and the task
state of ``n`` environments (:class:`~pectoral_gym.envs.tasks.table.TaskState`,
the task table's arrays and functions, shared with the robot env). The single
environment is an ``EnvCore`` with ``n = 1``; the vector environment uses one
with ``n = num_envs``. Its settings are an :class:`~pectoral_gym.envs.config.EnvConfig`
(re-exported here, with ``env_signature``, ``MODELS``, ``TASKS`` and ``task_info``).
Nothing here imports Gymnasium.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from pectoral_gym.envs.config import MODELS, TASKS, EnvConfig, env_signature
from pectoral_gym.envs.fused import FusedStep
from pectoral_gym.envs.fused_reset import FusedReset
from pectoral_gym.envs.layout import ACTION_SIZE, FishConstants, ReferenceEllipse, fish_array
from pectoral_gym.envs.sensed import SensedObservation
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.envs.tasks.table import TaskState, task_info
from pectoral_gym.envs.timing import ControlTiming
from pectoral_gym.model.jit import entry_point
from pectoral_gym.model.models import REST, FishModel
from pectoral_gym.model.params import FishParams

__all__ = ["EnvConfig", "EnvCore", "MODELS", "TASKS", "env_signature", "task_info"]


class EnvCore:
    """``n`` fish environments on one batched model: reset, step, and the arrays they fill.

    The packed arrays are those of ``task_state`` (laid out in :mod:`pectoral_gym.envs.layout`); read
    them through the accessors (``target``, ``reference``, ``fish_state``, ...).

    Args:
        n: Number of environments.
        config: The settings.

    Attributes:
        model: The batched :class:`~pectoral_gym.model.models.FishModel` (``n`` fish).
        task_state: The :class:`~pectoral_gym.envs.tasks.table.TaskState` whose arrays follow (the same objects).
        obs: ``(n, 19)`` float32 observations after the last reset/step, ``(n, 27)`` with ``observe_fins``
            (``envs.observation``).
        out: ``(n, N_OUT)`` reward, terms and flags of the last step (``layout.O_*``).
        ep: ``(n, N_EP)`` per-episode state (``layout.E_*``).
        fish: ``(n, N_FISH)`` values derived from each env's parameters (``layout.F_*``).
        beats: ``(n, 2, 4)`` commanded fin patterns ``(bias, amplitude, period, ratio)``, right fin first.
        params: The :class:`FishParams` of each env's current episode.
        sensed: With ``config.sensing``, the :class:`~pectoral_gym.envs.sensed.SensedObservation` that rewrites
            ``obs`` through the simulated camera and observer after every reset and step; else ``None``.
        timing: The :class:`~pectoral_gym.envs.timing.ControlTiming` that draws each step's command delay and
            period length with ``config.timing`` (without it: none, periods of ``control_period``).
        action_buffer: ``(n, 8)`` float64 actions; writing into it, then calling :meth:`buffer_step`'s
            function is the single env's path (no copy; a step is one compiled call,
            :class:`~pectoral_gym.envs.fused.FusedStep`).
    """

    def __init__(self, n: int, config: EnvConfig):
        self.n = int(n)
        self.config = config
        self.task = config.task_id
        # The task arrays and functions: one TaskState, shared with the robot env (envs.task_core).
        self.task_state = ts = TaskState(self.n, config)
        self.terms = ts.task.terms
        self.model: FishModel = config.model_spec().build(self.n, config.params)
        self.dt = float(config.control_period)
        self._observe_fins = bool(config.observe_fins)
        self._observe_fins_call = None  # the fin block's compiled entry point, bound at its first call
        self._period_max = float(config.period_range[1])
        self.cfg, self.ep, self.obs, self.out, self.beats, self.fish = ts.cfg, ts.ep, ts.obs, ts.out, ts.beats, ts.fish
        self.action_buffer = np.zeros((self.n, ACTION_SIZE))
        self._integral_before = np.zeros((self.n, 3))  # the model's velocity integrals before a step
        self.all = np.ones(self.n, dtype=np.bool_)
        self.none = ts.none
        self.action_code = ts.action_code
        self.params: list[FishParams] = [config.params] * self.n
        # The step: one compiled call (envs.fused), serial or parallel by batch size, with the task row's
        # kernel. Holds the arrays above and the model's: they are updated in place, never replaced.
        self.timing = ControlTiming(self.n, self.dt, config.timing)
        self.sensed = None if config.sensing is None else SensedObservation(self.model, config.sensing, self.dt,
                                                                            self.timing.longest_period)
        # Neither camera nor control timing: a step is the compiled call, the fin block in it, nothing else.
        self._plain = self.sensed is None and self.timing.settings is None
        self._step = FusedStep(self.model, self.dt, self.action_buffer, self.cfg, self.beats, self.obs, self.out,
                               self.fish, self.ep, self._integral_before, ts.task.reward_one, self.timing.timing,
                               self._period_max if self._observe_fins and self._plain else None)
        # One env, no camera, timing or randomised parameters, the built-in start: a reset after its draws is
        # one compiled call (envs.fused_reset), on the step's arrays.
        self._reset_one = None
        if (self.n == 1 and self._plain and not config.randomize and ts.task.start is tk.start_states
                and type(self.model).reset is FishModel.reset):
            self._reset_one = FusedReset(self._step, *self.model.start_rows(REST, REST), REST.as_array(),
                                         ts.action_code)
        if config.randomize:
            self._rand_names = tuple(config.randomize)
            widths = np.array([config.randomize[k] for k in self._rand_names])
            self._rand_low, self._rand_high = 1.0 - widths, 1.0 + widths
            self._rand_base = np.array([float(getattr(config.params, k)) for k in self._rand_names])

    def __getstate__(self) -> dict:
        """Pickle and deepcopy without the fin block's entry point (compiled code); a copy binds its own."""
        state = self.__dict__.copy()
        state["_observe_fins_call"] = None
        return state

    def reset(self, index: np.ndarray, rngs: Sequence[np.random.Generator], pinned: np.ndarray | None = None) -> None:
        """Start new episodes for the envs in ``index``; env ``i`` draws only from ``rngs[i]``.

        Per env, in this order: the randomisation factors (one per field of
        ``config.randomize``, in its order), then the task's draws (``TaskState.draw``), then, with
        ``config.sensing``, the camera's levels and the first frame's noise (``SensedObservation.reset``),
        then, with ``config.timing``, the episode's command delay level (``ControlTiming.reset``).
        ``pinned`` ``(len(index), 8)``, goal task: draws that replace the drawn ones where not NaN
        (``X, Y, psi, goal X, goal Y``; :func:`pin_start`); the generators draw as without it.
        """
        index = np.asarray(index, dtype=np.int64)
        if self._reset_one is not None and index.tolist() == [0]:  # the same steps, after the draws in one call
            draws = self.task_state.draw(rngs[0])
            if pinned is not None:
                draws = np.where(np.isnan(pinned[0]), draws, pinned[0])
            self._reset_one(draws)
            self.model.time = 0.0  # as FishModel.reset of every fish
            self.timing.reset(index, rngs)
            return
        draws = np.empty((index.size, 8))
        for k, i in enumerate(index.tolist()):  # Python ints: cheaper to iterate and index with
            rng = rngs[i]
            if self.config.randomize:
                factors = rng.uniform(self._rand_low, self._rand_high)
                changes = dict(zip(self._rand_names, (self._rand_base * factors).tolist(), strict=True))
                self.params[i] = self.config.params.replace(**changes)
                self.model.set_params(self.params[i], i)
            draws[k] = self.task_state.draw(rng)
        if pinned is not None:
            draws = np.where(np.isnan(pinned), draws, pinned)
        if self.config.randomize:
            self.fish[index] = fish_array([self.params[i] for i in index])
        start = self.task_state.start(index, draws)
        self.model.reset(start, right=REST, left=REST, index=None if index.size == self.n else index)
        self.task_state.observe_reset(index, self.model.state)
        if self.sensed is not None:
            self.sensed.reset(index, rngs, self.model.state, self.ep, self.fish, self.obs)
        self.timing.reset(index, rngs)
        self._observe_fin_block()

    def step(self, actions: np.ndarray, skip: np.ndarray | None = None) -> None:
        """Apply ``actions`` ``(n, 8)`` for one control period (envs in ``skip`` are not checked or scored).

        Raises:
            ValueError: If an action of an env not in ``skip`` is not finite, or ``actions`` does not
                have shape ``(n, 8)``.
        """
        if self._plain:  # the simulated env's usual step: the compiled call, which writes the fin block too
            bad = self._step(actions, skip)
            if bad >= 0:
                self._raise_non_finite(actions, bad)
            return
        sensed = self.sensed
        if sensed is not None:
            sensed.before_step(self.model)
        if self.timing.settings is not None:  # a step that raises draws nothing
            self._check_actions(actions, skip)
            self.timing.draw_step(skip)  # the envs' generators: a step's timing first, then the camera's frames
        bad = self._step(actions, skip)
        if bad >= 0:
            self._raise_non_finite(actions, bad)
        if sensed is not None:  # the observation through the camera (the envs' generators: after the reset's)
            sensed.step(self.none if skip is None else np.asarray(skip, dtype=np.bool_), self.model,
                        self._step.settings(), self.beats, self.ep, self.fish, self.obs, self.timing.timing)
        self._observe_fin_block()

    def buffer_step(self) -> Callable[[], int]:
        """A function that runs ``step(action_buffer)`` and returns -1, or, for a non-finite action, the env's index.

        For that index nothing was written; :meth:`raise_non_finite` raises the step's error. Without camera and
        control timing it is the fused step's own (one Python call, :meth:`FusedStep.step_buffer`), else
        :meth:`step`, which raises itself.
        """
        return self._step.step_buffer if self._plain else self._step_action_buffer

    def _step_action_buffer(self) -> int:
        self.step(self.action_buffer)
        return -1

    def raise_non_finite(self, bad: int) -> None:
        """Raise :meth:`step`'s error for env ``bad``'s non-finite action in the action buffer."""
        self._raise_non_finite(self.action_buffer, bad)

    def _observe_fin_block(self) -> None:
        """With ``observe_fins``: the observation's fin block from the model's half-strokes."""
        if self._observe_fins:
            call = self._observe_fins_call
            if call is None:  # its entry point: the arrays' types are fixed (updated in place, never replaced)
                call = self._observe_fins_call = entry_point(tk.observe_fins, (self.model.fins, self.obs,
                                                                               self._period_max))
            call(self.model.fins, self.obs, self._period_max)

    def _check_actions(self, actions: np.ndarray, skip: np.ndarray | None) -> None:
        """Raise as :meth:`step` would for actions of the wrong shape or non-finite ones (before any draw)."""
        arr = np.asarray(actions, dtype=np.float64)
        if arr.shape != self.action_buffer.shape:
            raise ValueError(f"actions must have shape {self.action_buffer.shape}, got {arr.shape}")
        bad = tk.first_non_finite(arr, self.none if skip is None else np.asarray(skip, dtype=np.bool_))
        if bad >= 0:
            self._raise_non_finite(arr, bad)

    def _raise_non_finite(self, actions: np.ndarray, bad: int) -> None:
        where = f" for env {bad}" if self.n > 1 else ""
        raise ValueError(f"action must be finite, got {np.asarray(actions[bad]).tolist()}{where}")

    # ------------------------------------------------------------ accessors (copies, plain floats)
    def target(self, i: int) -> tuple[float, float]:
        """Target position of env ``i`` in the tank frame [m]."""
        return float(self.ep[i, tk.E_TX]), float(self.ep[i, tk.E_TY])

    def target_velocity(self, i: int) -> tuple[float, float]:
        """Target velocity of env ``i`` in the tank frame [m/s] (zero for ``goal``)."""
        return float(self.ep[i, tk.E_TVX]), float(self.ep[i, tk.E_TVY])

    def set_target(self, i: int, x: float, y: float) -> None:
        """Move the target of env ``i`` to ``(x, y)`` [m] (tank frame); the observation shows it after the next step.

        For ``goal`` the target stays there; for ``track`` the next step moves it on along the ellipse.
        """
        self.ep[i, tk.E_TX], self.ep[i, tk.E_TY] = float(x), float(y)

    def reference(self, i: int) -> ReferenceEllipse:
        """The reference ellipse of env ``i`` (``track``; all zero for ``goal``)."""
        return ReferenceEllipse(*self.ep[i, tk.E_CX:tk.E_PHASE + 1].tolist())

    def fish_constants(self, i: int) -> FishConstants:
        """The values of env ``i``'s parameters that the task kernels use (body length, fin span, drag constant)."""
        return FishConstants(*self.fish[i].tolist())

    def fish_state(self, i: int) -> np.ndarray:
        """Model state ``(X, Y, psi, vx, vy, omega)`` of env ``i`` (a copy) [m, m, rad, m/s, m/s, rad/s]."""
        return self.model.state[i].copy()

    def set_fish_state(self, i: int, state: Sequence[float]) -> None:
        """Overwrite the model state of env ``i`` (fins and velocity integrals are kept); takes effect at the next step.

        Raises:
            ValueError: If ``state`` is not 6 finite numbers.
        """
        value = np.asarray(state, dtype=np.float64)
        if value.shape != (6,) or not np.all(np.isfinite(value)):
            raise ValueError(f"state must be 6 finite numbers (X, Y, psi, vx, vy, omega), got {state!r}")
        self.model.state[i] = value

    def fin_patterns(self, i: int) -> np.ndarray:
        """Commanded fin patterns ``(2, 4)`` of env ``i``: ``(bias, amplitude, period, ratio)``, right fin first."""
        return self.beats[i].copy()
