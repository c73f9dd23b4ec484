"""The task table and the task state: one place for every fish task, shared by the simulated and the robot envs.

A *task* is what turns a fish state into an episode: how its target is drawn
and where the fish starts, the reward terms and the termination after each
control period, and the keys of ``info``. Every task is one row of :data:`TASK_TABLE`
(:class:`~pectoral_gym.envs.tasks.row.Task`); :class:`TaskState` holds the task arrays of ``n`` envs (one
fish each, laid out in :mod:`pectoral_gym.envs.layout` and
:mod:`pectoral_gym.envs.observation`) and runs the row's functions on them. The
simulated envs (:class:`~pectoral_gym.envs.core.EnvCore`: the model's state) and
:class:`pectoral_gym.hardware.env.HardwareFishEnv` (the observer's estimate of the real fish)
use the same ``TaskState``, so for the same fish states and commands they give
the same observations, rewards and ``info``. Nothing here imports Gymnasium.

Per step a ``TaskState`` maps the action to fin patterns and prices their
energy (:meth:`TaskState.apply`), and after the fish moved writes the
observation, reward terms and flags (:meth:`TaskState.observe`); the observed
velocities are the means over the control period (the simulated envs: the
model's velocity integrals; the robot: the observer's estimates,
:meth:`TaskState.set_mean_velocity`). :meth:`TaskState.info` builds ``info``:
the row's reward terms in summation order, ``"distance"``, then the row's
``extra_info`` (``is_success`` for ``goal``, ``tracking_error`` for ``track``).

Adding a task touches this table only: call :func:`register_task` with

* ``terms``: ``(info key, out index)`` of each reward term, in summation order
  (any of the ``layout.O_*`` term slots);
* ``draw(rng, cfg) -> (8,)``: the episode's random numbers, drawn from ``rng`` only (``cfg``: the packed
  settings, e.g. the goal task's insets);
* ``start(index, draws, cfg, ep, start)``: from the draws, write the targets of
  the envs in ``index`` into ``ep`` (``E_TX .. E_TVY``, tank frame) and their
  start states ``(X, Y, psi, 0, 0, 0)`` into ``start``;
* ``reward_one(i, state, cfg, ep, fish, obs, out)``: a ``numba.njit`` kernel
  for env ``i`` after a control period: write ``obs`` with :func:`observe_fish`,
  then ``out`` (the terms, ``O_REWARD`` = their sum, ``O_DISTANCE``,
  ``O_TERMINATED``, ``O_SUCCESS``) and ``ep[i, E_DPREV]``; ``out[i, O_ENERGY]``
  holds the energy term on entry;
* optionally ``extra_info`` (``(key, out index, flag)``, a flag reads
  ``out > 0.5`` as a ``np.bool_``) and ``fit_start(draws, x, y, rng, cfg)``, which
  adapts the draws to a measured start pose (the robot starts where it is).

With ``stop_band`` (``cfg[C_BAND]``) the built-in kernel also ends the episode when any part of the fish is
inside the robot's stopping band (:func:`pectoral_gym.envs.tasks.kernels.in_band`), prices it as a wall
contact and writes ``out[O_COST]``; :meth:`TaskState.info` then adds ``"cost"``.

The task is then a valid ``task=`` of ``gym.make("PectoralFish-*-v0")``, of the
vector env and of ``HardwareFishEnv`` (``tests/test_task_core.py`` registers one).
New settings (weights) need an ``EnvConfig`` field and a ``cfg`` slot; reuse the
existing ones where they fit. The built-in tasks share one kernel,
``tasks.reward_one``, branching on ``cfg[C_TASK]`` (faster than one call per task).
The loops over the envs are written once (:func:`observe_body` here, the env step
``envs.fused.step_body``) and compiled with the row's kernel bound in
(:func:`pectoral_gym.model.jit.kernel_builds`; no code is generated; a registered task's
builds are not cached on disk: its code lives in the caller's file).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, Protocol

import numba as nb
import numpy as np
from numba.core.dispatcher import Dispatcher

from pectoral_gym.envs.layout import (
    C_BAND,
    GOAL,
    N_EP,
    N_OUT,
    O_COST,
    O_DISTANCE,
    O_ENERGY,
    O_GOAL,
    O_PROGRESS,
    O_SUCCESS,
    O_TIME,
    O_TRACKING,
    O_WALL,
    TRACK,
    fish_array,
)
from pectoral_gym.envs.observation import OBS_VELOCITY, observation_size
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.envs.tasks.row import InfoField, Task
from pectoral_gym.model.jit import Kernel, KernelPair, entry_point, kernel_builds
from pectoral_gym.model.models import REST
from pectoral_gym.model.params import FishParams

__all__ = ["TASK_TABLE", "TASK_IDS", "TaskSettings", "TaskState", "register_task", "unregister_task",
           "task_by_id", "task_info", "observe_fish", "observe_body"]

#: ``observe_fish(i, state, ep, fish, obs) -> (distance [m], wall contact)``: env ``i``'s observation up to
#: the last action (the one observation builder, :mod:`pectoral_gym.envs.tasks.kernels`), for a task's ``reward_one``.
observe_fish = tk.observe_one

_BUILTIN = (GOAL, TRACK)


def observe_body(state, skip, cfg, ep, fish, obs, out):
    """Observation, reward terms and flags of every env not in ``skip``: the task's ``reward_one`` per env.

    Compiled per task row with its ``reward_one`` bound (:func:`pectoral_gym.model.jit.kernel_builds`).
    """
    for i in nb.prange(state.shape[0]):
        if not skip[i]:
            reward_one(i, state, cfg, ep, fish, obs, out)


reward_one = tk.reward_one  # the built-in tasks' kernel, the global observe_body calls
_OBSERVE = kernel_builds(observe_body, name="_observe")


def _observe_builds(task_kernel: Callable[..., Any]) -> KernelPair:
    """:func:`observe_body`'s builds for ``task_kernel`` (the built-in ones cached on disk)."""
    if task_kernel is tk.reward_one:
        return _OBSERVE
    return kernel_builds(observe_body, name="_observe_registered", bindings={"reward_one": task_kernel}, cache=False)


# ---------------------------------------------------------------- the built-in tasks
def _fit_goal(draws: np.ndarray, x: float, y: float, rng: np.random.Generator, cfg: np.ndarray) -> None:
    """Goal at a measured start ``(x, y)``: redraw the goal (as :func:`tasks.draw_episode`) until 0.3-1.0 m away."""
    inset = cfg[tk.C_GOAL_INSET]
    for _ in range(tk.GOAL_MAX_BLOCKS * tk.GOAL_CANDIDATES):
        if tk.GOAL_MIN_DISTANCE <= math.hypot(draws[3] - x, draws[4] - y) <= tk.GOAL_MAX_DISTANCE:
            return
        u = rng.random(2)
        draws[3] = inset + u[0] * (tk.TANK_X - 2.0 * inset)
        draws[4] = inset + u[1] * (tk.TANK_Y - 2.0 * inset)


def _goal_info(out: np.ndarray) -> dict:
    """``goal``'s info as a dict display (the fastest dict Python builds); checked against its fields."""
    return {"reward_progress": out[O_PROGRESS], "reward_goal": out[O_GOAL], "reward_wall": out[O_WALL],
            "reward_energy": out[O_ENERGY], "reward_time": out[O_TIME], "distance": out[O_DISTANCE],
            "is_success": out[O_SUCCESS] > 0.5}


def _track_info(out: np.ndarray) -> dict:
    """``track``'s info as a dict display; checked against its fields."""
    return {"reward_tracking": out[O_TRACKING], "reward_wall": out[O_WALL], "reward_energy": out[O_ENERGY],
            "distance": out[O_DISTANCE], "tracking_error": out[O_DISTANCE]}


TASK_TABLE: dict[str, Task] = {
    "goal": Task("goal", GOAL, tk.TERMS[GOAL], (InfoField("is_success", O_SUCCESS, flag=True),),
                 lambda rng, cfg: tk.draw_episode(rng, GOAL, cfg), tk.start_states, tk.reward_one, _OBSERVE,
                 fit_start=_fit_goal, info=_goal_info),
    "track": Task("track", TRACK, tk.TERMS[TRACK], (InfoField("tracking_error", O_DISTANCE),),
                  lambda rng, cfg: tk.draw_episode(rng, TRACK, cfg), tk.start_states, tk.reward_one, _OBSERVE,
                  info=_track_info),
}
_BY_ID: dict[int, Task] = {t.id: t for t in TASK_TABLE.values()}


class _TaskIds(Mapping):
    """Live read-only view ``name -> id`` of :data:`TASK_TABLE`."""

    def __getitem__(self, name: str) -> int:
        return TASK_TABLE[name].id

    def __iter__(self) -> Iterator[str]:
        return iter(TASK_TABLE)

    def __len__(self) -> int:
        return len(TASK_TABLE)

    def __repr__(self) -> str:
        return repr(dict(self))


#: ``name -> cfg[C_TASK]`` of every registered task (a live view of the table).
TASK_IDS: Mapping[str, int] = _TaskIds()


def task_by_id(task: int) -> Task:
    """The table row with this ``cfg[C_TASK]`` id; raises ``ValueError`` for an unknown id."""
    try:
        return _BY_ID[int(task)]
    except KeyError:
        raise ValueError(f"no task with id {task!r}; registered: {TASK_IDS!r}") from None


def task_info(out: np.ndarray, task: int) -> dict:
    """The ``info`` of one env from its ``out`` row (``layout.O_*``), numpy scalars (:attr:`Task.info_fields`)."""
    return _BY_ID[task].info(out)


# ---------------------------------------------------------------- registering a task
def register_task(name: str, *, terms: Sequence[tuple[str, int]],
                  draw: Callable[[np.random.Generator, np.ndarray], np.ndarray],
                  start: Callable[..., Any], reward_one: Callable[..., Any],
                  extra_info: Sequence[InfoField | tuple] = (),
                  fit_start: Callable[[np.ndarray, float, float, np.random.Generator, np.ndarray], None] | None = None
                  ) -> Task:
    """Add a task to the table (module docstring); it is then a valid ``task=`` of every fish env.

    Returns:
        The new row, with the next free id.

    Raises:
        ValueError: If the name is taken or not an identifier, the terms are empty, or an info key repeats.
        TypeError: If ``reward_one`` is not a ``numba.njit`` function or ``draw``/``start`` are not callable.
    """
    if not (isinstance(name, str) and name.isidentifier()):
        raise ValueError(f"a task name must be an identifier, got {name!r}")
    if name in TASK_TABLE:
        raise ValueError(f"task {name!r} is already registered (unregister_task first)")
    if not isinstance(reward_one, (Dispatcher, Kernel)):
        raise TypeError(f"reward_one must be a numba.njit function (i, state, cfg, ep, fish, obs, out), "
                        f"got {reward_one!r}")
    if not (callable(draw) and callable(start)):
        raise TypeError("draw and start must be callables (module docstring)")
    terms = tuple((str(k), int(i)) for k, i in terms)
    if not terms:
        raise ValueError("a task needs at least one reward term")
    extra = tuple(InfoField(*f) for f in extra_info)
    keys = [k for k, _ in terms] + ["distance"] + [f.key for f in extra]
    if len(set(keys)) != len(keys):
        raise ValueError(f"info keys repeat: {keys}")
    task = Task(name, max(_BY_ID) + 1, terms, extra, draw, start, reward_one, _observe_builds(reward_one), fit_start)
    TASK_TABLE[name] = task
    _BY_ID[task.id] = task
    return task


def unregister_task(name: str) -> None:
    """Remove a registered task; the built-in ``goal`` and ``track`` stay (``ValueError``)."""
    task = TASK_TABLE.get(name)
    if task is None:
        raise ValueError(f"task {name!r} is not registered; registered: {list(TASK_TABLE)}")
    if task.id in _BUILTIN:
        raise ValueError(f"the built-in task {name!r} cannot be removed")
    del TASK_TABLE[name], _BY_ID[task.id]


# ---------------------------------------------------------------- the task state of n envs
_REST_BEAT = REST.as_array()  # the rest pattern's row, made once
_REST_BEAT.flags.writeable = False


def _plain(array: Any, dtype: type, ndim: int) -> bool:
    """Whether ``array`` has the numba type of a writable, aligned, C-contiguous ``ndim``-d ``dtype`` ndarray."""
    if type(array) is not np.ndarray or array.dtype != dtype or array.ndim != ndim:
        return False
    flags = array.flags
    return flags.c_contiguous and flags.writeable and flags.aligned


class TaskSettings(Protocol):
    """What :class:`TaskState` reads of its settings (:class:`~pectoral_gym.envs.core.EnvConfig` has it all)."""

    task: str
    observe_fins: bool
    params: FishParams

    def cfg_array(self) -> np.ndarray:
        """The packed settings ``(N_CFG,)`` (:mod:`pectoral_gym.envs.layout`)."""
        ...

    def encode(self, beat: np.ndarray) -> np.ndarray:
        """Normalised action entries of one fin pattern."""
        ...


class TaskState:
    """The task arrays of ``n`` envs, one fish each, and the operations of a task on them.

    The simulated envs feed it the model's state, the robot env the observer's estimate.

    Args:
        n: Number of envs.
        config: The settings (an :class:`~pectoral_gym.envs.core.EnvConfig`: :class:`TaskSettings`);
            ``config.task`` names the row.

    Attributes:
        task: The :class:`Task` row.
        cfg: ``(N_CFG,)`` packed settings; ``ep`` ``(n, N_EP)``, ``fish`` ``(n, N_FISH)``,
            ``out`` ``(n, N_OUT)``, ``beats`` ``(n, 2, 4)``: :mod:`pectoral_gym.envs.layout`.
        obs: ``(n, OBS_SIZE)`` float32 observations (:mod:`pectoral_gym.envs.observation`; wider with
            ``config.observe_fins``, whose block :class:`~pectoral_gym.envs.core.EnvCore` writes).
        action_code: The normalised action of the rest pattern, the last action after a reset.
    """

    def __init__(self, n: int, config: TaskSettings):
        self.n = int(n)
        self.config = config
        self.task = TASK_TABLE[config.task]
        self.cfg = config.cfg_array()
        self.ep = np.zeros((self.n, N_EP))
        self.obs = np.zeros((self.n, observation_size(config.observe_fins)), dtype=np.float32)
        self.out = np.zeros((self.n, N_OUT))
        self.beats = np.broadcast_to(REST.as_array(), (self.n, 2, 4)).copy()
        self.fish = fish_array([config.params] * self.n)
        self.action_code = np.concatenate([config.encode(REST.as_array())] * 2)
        self.none = np.zeros(self.n, dtype=np.bool_)

    def __getstate__(self) -> dict[str, Any]:
        """Pickle the row by name (its functions are looked up again from the table), without compiled code."""
        state = self.__dict__.copy()
        state["task"] = self.task.name
        state.pop("_observe_reset_call", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if self.task not in TASK_TABLE:
            raise ValueError(f"task {self.task!r} is not registered in this process (register_task first)")
        self.task = TASK_TABLE[self.task]

    # ------------------------------------------------------------ reset
    def draw(self, rng: np.random.Generator) -> np.ndarray:
        """One episode's random numbers ``(8,)`` from ``rng``.

        Raises:
            ValueError: If the row's ``draw`` gives another shape.
        """
        draws = self.task.draw(rng, self.cfg)
        if (draws.shape if type(draws) is np.ndarray else np.shape(draws)) != (8,):
            raise ValueError(f"task {self.task.name!r}: draw(rng) must give 8 numbers, got shape {np.shape(draws)}")
        return draws

    def start(self, index: np.ndarray, draws: np.ndarray) -> np.ndarray:
        """Targets of the envs in ``index`` from ``draws`` ``(len(index), 8)``; returns the start states ``(k, 6)``."""
        start = np.empty((len(index), 6))
        self.task.start(index, draws, self.cfg, self.ep, start)
        return start

    def observe_reset(self, index: np.ndarray, state: np.ndarray) -> None:
        """Observe freshly reset envs (fish ``state`` ``(n, 6)``); ``out`` zero but the distance; rest beats."""
        self.beats[index] = _REST_BEAT
        args = (index, state, self.ep, self.fish, self.obs, self.out, self.action_code)
        if _plain(index, np.int64, 1) and _plain(state, np.float64, 2):  # the entry point's types
            call = self.__dict__.get("_observe_reset_call")
            if call is None:  # the task arrays' types are fixed (updated in place, never replaced)
                call = self._observe_reset_call = entry_point(tk.observe_reset, args)
            call(*args)
        else:
            tk.observe_reset(*args)

    def reset_at(self, i: int, rng: np.random.Generator, pose: Sequence[float]) -> None:
        """Start env ``i``'s episode with the fish at a measured ``pose`` ``(X, Y, psi)``, at rest (the robot).

        The draws are those of a simulated reset, adapted to the pose by the row's ``fit_start``.
        """
        x, y, psi = (float(v) for v in pose)
        index = np.array([i], dtype=np.int64)
        draws = self.draw(rng)
        if self.task.fit_start is not None:
            self.task.fit_start(draws, x, y, rng, self.cfg)
        self.start(index, draws[None])
        state = np.zeros((self.n, 6))
        state[i, :3] = x, y, psi
        self.observe_reset(index, state)

    # ------------------------------------------------------------ step
    def apply(self, actions: np.ndarray, skip: np.ndarray | None = None) -> int:
        """Actions ``(n, 8)`` to fin patterns, last-action observation and energy term (``tasks.apply_actions``).

        Returns:
            -1, or the first env whose action is not finite (then nothing was written).
        """
        return tk.apply_actions(actions, self.none if skip is None else skip, self.cfg, self.beats, self.obs,
                                self.out, self.fish)

    def observe(self, state: np.ndarray, skip: np.ndarray | None = None) -> None:
        """After a control period with the fish at ``state`` ``(n, 6)``: observation, reward terms and flags.

        The velocity entries are ``state``'s; overwrite them with the means over the period
        (:meth:`set_mean_velocity`) as the simulated envs do.
        """
        self.task.observe.run(state, self.none if skip is None else skip, self.cfg, self.ep, self.fish, self.obs,
                             self.out)

    def set_mean_velocity(self, i: int, velocity: Sequence[float]) -> None:
        """Observe ``(vx, vy, omega)`` [m/s, m/s, rad/s], the mean over the last control period, for env ``i``."""
        self.obs[i, OBS_VELOCITY] = velocity

    @property
    def info_fields(self) -> tuple[InfoField, ...]:
        """Every ``info`` entry in order: the row's (:attr:`Task.info_fields`), then ``"cost"`` with ``stop_band``."""
        fields = self.task.info_fields
        return (*fields, InfoField("cost", O_COST)) if self.cfg[C_BAND] > 0.5 else fields

    def info(self, i: int) -> dict:
        """Env ``i``'s ``info`` after the last reset or step (:attr:`info_fields`), numpy scalars."""
        info = self.task.info(self.out[i])
        if self.cfg[C_BAND] > 0.5:
            info["cost"] = self.out[i, O_COST]
        return info

    def reward(self, i: int) -> float:
        """Env ``i``'s reward of the last step."""
        return float(self.out[i, tk.O_REWARD])

    def terminated(self, i: int) -> bool:
        """Whether env ``i``'s episode ended at the last step (task ends only)."""
        return bool(self.out[i, tk.O_TERMINATED] > 0.5)

