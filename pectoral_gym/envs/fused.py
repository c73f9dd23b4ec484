"""The env step: one compiled body, in a serial and a parallel build chosen by batch size.

:class:`~pectoral_gym.envs.core.EnvCore` steps its envs with one compiled call, :func:`step_body`,
which runs, in this order:

1. ``tasks.first_non_finite``: a non-finite action of an env not in ``skip`` stops the step
   before anything is written (its index is returned);

then, env by env (each touches only its own rows, so the order across envs does not matter):

2. ``tasks.apply_keep_one``: keep the velocity integrals, map the action to fin patterns, write
   the last action and the energy term;
3. ``strokes.command_one``: command the fish's fins (``FishModel.command_array``);
4. ``stepping.advance_one``: advance the fish one control period (``FishModel.advance``; each model's
   builds call that model's own kernel, ``stepping.ADVANCE_ONE``);
5. the task's ``reward_one`` unless the env is in ``skip`` (the task table's row; the built-in
   tasks share ``tasks.reward_one``), then ``tasks.observe_mean_velocity``: the observed
   velocities are the means over the control period.

With the env's control timing (``timing``, ``(n, 2)``: :mod:`pectoral_gym.envs.timing`) env ``i``'s
period lasts ``timing[i, SPAN]`` seconds and its command is taken ``timing[i, LAG]`` seconds into it
(steps 3-4 become: advance ``LAG`` on the previous command, command, advance the rest). Without it
``LAG = 0`` and ``SPAN`` is the control period: the same arithmetic as steps 3-4 above.

The per-env loop is a ``numba.prange`` loop: :func:`pectoral_gym.model.jit.kernel_builds` compiles it
serially (below ``PARALLEL_MIN_ITEMS`` envs, where threads cost more than they save) and in
parallel; every env's arithmetic is the same in both, so the two give the same bits
(``tests/test_fused_step.py``). One loop is one parallel region per step: its threads meet once,
and take its envs in chunks of :data:`CHUNK` as they come free (set around the call, from Python).
A task registered at run time gets builds of the same body with its kernel bound in place of
``reward_one`` (:func:`step_builds`).

The arrays of one core are bound once into a :class:`StepArrays` (a numba structref that holds
them, not copies) with the model's settings (:class:`StepSettings`), an all-false skip mask and
the fin block's setting, so the usual step, :func:`step_own`, passes that one object (numba unboxes
one argument, not three) and also writes the observation's fin block (``observe_fins``); a step
with a skip mask runs :func:`step_body` with the mask and the settings. Each is called through its
compiled entry point of that exact signature (:func:`pectoral_gym.model.jit.entry_point`), which
skips numba's argument typing (about 1 us for a structref).
Inside the body the arrays are :func:`borrow`-ed views: numba's reference counts, which every
inlined kernel that takes an array would otherwise update atomically (shared by the threads), are
not touched.

This body inlines code from many modules; like every kernel it is compiled with
:func:`pectoral_gym.model.jit.njit`, whose disk cache is keyed on all the sources it compiles from.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numba as nb
import numpy as np
from numba.core import types
from numba.experimental import structref

from pectoral_gym.envs.borrowed import borrow
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.model import stepping
from pectoral_gym.model.jit import (
    PARALLEL_MIN_ITEMS,
    Kernel,
    KernelPair,
    entry_point,
    kernel_builds,
    kernel_variant,
    njit,
)
from pectoral_gym.model.strokes import command_one
from pectoral_gym.model.threads import start_passive_threads

__all__ = ["CHUNK", "STEP", "STEP_FIELDS", "FusedStep", "StepArrays", "StepSettings", "borrow", "step_body",
           "step_builds", "step_own", "own_builds"]

@structref.register
class StepArraysType(types.StructRef):
    """numba type of :class:`StepArrays` (its fields' array types)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class StepArrays(structref.StructRefProxy):
    """The arrays one env core steps, held by reference for the compiled step (fields: :data:`STEP_FIELDS`)."""


#: The fields of :class:`StepArrays`: the env core's arrays (``actions`` its action buffer,
#: ``before`` its velocity integrals before the step, ``everyone`` an all-true mask, ``timing`` each
#: env's command delay and period length), then the model's arrays and its K tables as
#: :func:`pectoral_gym.model.stepping.advance` takes them, then what :func:`step_own` passes on: the model's
#: settings (a :class:`StepSettings`), an all-false skip mask (``none``) and the fin block's largest period
#: (``fin_period`` [s]; 0: no fin block).
STEP_FIELDS = ("actions", "cfg", "beats", "obs", "out", "fish", "ep", "before", "everyone", "timing",
               "state", "fins", "cache", "pending", "integral", "coef", "tables", "settings", "none", "fin_period")
structref.define_proxy(StepArrays, StepArraysType, list(STEP_FIELDS))


@njit
def new_step_arrays(actions, cfg, beats, obs, out, fish, ep, before, everyone, timing, state, fins, cache, pending,
                    integral, coef, tables, settings, none, fin_period):
    """A :class:`StepArrays` of these arrays; compiled and cached (``StepArrays(...)`` compiles anew per process)."""
    return StepArrays(actions, cfg, beats, obs, out, fish, ep, before, everyone, timing, state, fins, cache, pending,
                      integral, coef, tables, settings, none, fin_period)


class StepSettings(NamedTuple):
    """The model's settings of one step, as :func:`pectoral_gym.model.stepping.advance` takes them.

    Attributes:
        duration: Control period [s].
        dt_max: Largest RK4 substep [s].
        min_substeps: Full model: least number of substeps per half-stroke (a float).
        averaged: Integrate the averaged model (eq. 25) instead of the full one (eq. 19).
        mode: Averaged forcing form (``averaging.EXACT`` or ``averaging.TAYLOR``).
        corrections: Averaged model's corrections (``stroke_corrections.corrections``).
    """

    duration: float
    dt_max: float
    min_substeps: float
    averaged: bool
    mode: int
    corrections: int


#: Envs per chunk of the parallel build's loop: each thread takes the next chunk when it is free, so a
#: thread that starts late (woken from its passive wait, or not scheduled on a loaded machine) or meets
#: slower envs does not hold the others up.
CHUNK = 32
reward_one = tk.reward_one  # the task kernel the body calls (the built-in tasks'; step_builds rebinds it)
advance_one = stepping.advance_one  # the model's kernel the body calls (either model; the builds bind their own)


def step_body(a, skip, s):
    """Step the envs of ``a`` (a :class:`StepArrays`) except those where ``skip``, with settings ``s``.

    Returns -1, or the index of the first env not in ``skip`` whose action is not finite (then
    nothing has been written). The steps are listed in the module docstring; every env's steps 2-5
    touch only its own rows, so one loop runs them env by env.
    """
    # The fields as borrowed views, read once: each read of a structref field, and each call that takes
    # an array, would take and drop a reference to it (atomic counts that the threads would share).
    actions, cfg, beats, obs, out = borrow(a.actions), borrow(a.cfg), borrow(a.beats), borrow(a.obs), borrow(a.out)
    fish, ep, before, everyone = borrow(a.fish), borrow(a.ep), borrow(a.before), borrow(a.everyone)
    timing = borrow(a.timing)
    state, fins, cache, pending = borrow(a.state), borrow(a.fins), borrow(a.cache), borrow(a.pending)
    integral, coef, packed = borrow(a.integral), borrow(a.coef), a.tables
    tables = (borrow(packed[0]), borrow(packed[1]), borrow(packed[2]), borrow(packed[3]), packed[4],
              borrow(packed[5]), borrow(packed[6]), borrow(packed[7]))
    duration, dt_max, min_substeps, averaged, mode, corrections = s
    bad = tk.first_non_finite(actions, skip)
    if bad >= 0:
        return bad
    n = actions.shape[0]
    # The parallel build's threads take chunks of CHUNK envs as they come free: set around the call (_chunked),
    # not here, where it would keep the kernel out of the disk cache (every process would compile it afresh).
    for i in nb.prange(n):
        tk.apply_keep_one(i, actions, skip, cfg, beats, obs, out, fish, integral, before)
        lag, span = timing[i, 0], timing[i, 1]
        if lag > 0.0:  # the command reaches the fins lag into the period (envs.timing)
            advance_one(i, state, fins, cache, pending, integral, coef, lag, dt_max, min_substeps, averaged, mode,
                        corrections, tables)
        command_one(i, fins, pending, beats, everyone)
        advance_one(i, state, fins, cache, pending, integral, coef, span - lag, dt_max, min_substeps, averaged, mode,
                    corrections, tables)
        if not skip[i]:
            reward_one(i, state, cfg, ep, fish, obs, out)
        tk.observe_mean_velocity(i, span, obs, integral, before)
    return -1


def step_own(a):
    """The usual step: :func:`step_body` of ``a`` with its own settings and no env skipped, then the fin block.

    With ``a.fin_period > 0`` (``observe_fins``) and a step taken, the observation's fin block of every
    env (``tasks.observe_fins``). Returns as :func:`step_body`. ``step`` is bound to the build of
    :func:`step_body` it runs (:func:`own_builds`): a compiled call, not the body inlined, so the parallel
    build keeps its threads.
    """
    bad = step(a, a.none, a.settings)
    if bad < 0:
        period = a.fin_period
        if period > 0.0:
            tk.observe_fins(borrow(a.fins), borrow(a.obs), period)
    return bad


step = None  # the build of step_body that step_own calls (bound in own_builds)


#: ``averaged`` -> the builds of :func:`step_body` for the built-in tasks on that model (cached on disk): each
#: calls its model's own kernel (``stepping.ADVANCE_ONE``), so an env compiles no code of the other model.
STEP = {averaged: kernel_builds(step_body, name=f"_step_{'averaged' if averaged else 'full'}",
                                bindings={"advance_one": kernel})
        for averaged, kernel in stepping.ADVANCE_ONE.items()}
_REGISTERED: dict[tuple[Any, bool], KernelPair] = {}


def step_builds(task_kernel: Callable[..., Any], averaged: bool) -> KernelPair:
    """The builds of :func:`step_body` on the ``averaged`` (else full) model, calling ``task_kernel`` as ``reward_one``.

    :data:`STEP` for ``tasks.reward_one``; for a task registered at run time, builds of the same
    body with its kernel bound (compiled at their first call, not cached on disk: the kernel's code
    lives in the caller's file).
    """
    averaged = bool(averaged)
    if task_kernel is tk.reward_one:
        return STEP[averaged]
    key = (task_kernel, averaged)
    if key not in _REGISTERED:
        _REGISTERED[key] = kernel_builds(step_body, name=f"_step_registered_{'averaged' if averaged else 'full'}",
                                         bindings={"reward_one": task_kernel,
                                                   "advance_one": stepping.ADVANCE_ONE[averaged]}, cache=False)
    return _REGISTERED[key]


_OWN: dict[tuple[Any, bool], tuple[Kernel, Kernel]] = {}


def own_builds(task_kernel: Callable[..., Any], averaged: bool) -> tuple[Kernel, Kernel]:
    """The serial and parallel builds of :func:`step_own`, each calling that build of :func:`step_builds`.

    Cached on disk for ``tasks.reward_one``; for a task registered at run time compiled at their first call.
    """
    averaged = bool(averaged)
    key = (task_kernel, averaged)
    if key not in _OWN:
        builds = step_builds(task_kernel, averaged)
        cache = task_kernel is tk.reward_one
        suffix = "averaged" if averaged else "full"
        name = f"_own_{suffix}" if cache else f"_own_registered_{suffix}"
        serial, parallel = (kernel_variant(step_own, f"{name}_{kind}", {"step": build}, cache=cache)
                            for kind, build in (("serial", builds.serial), ("parallel", builds.parallel)))
        _OWN[key] = serial, parallel
    return _OWN[key]


def _chunked(function: Callable[..., int]) -> Callable[..., int]:
    """``function`` run with numba's chunk size :data:`CHUNK`, then the caller's again (a per-thread setting).

    Set here, from Python: set inside the step body (``nb.parallel_chunksize``) it would link a pointer into
    numba's threading layer into the kernel, which keeps it out of the disk cache.
    """
    def run(*args: Any) -> int:
        previous = nb.set_parallel_chunksize(CHUNK)
        try:
            return function(*args)
        finally:
            nb.set_parallel_chunksize(previous)

    return run


class _Bound(NamedTuple):
    arrays: StepArrays
    kernel: Callable[..., int]  # the build (a dispatcher: any argument types; the parallel one in _chunked)
    call: Callable[..., int]  # its entry point for (arrays, a bool mask, settings), likewise
    own: Callable[..., int]  # step_own's entry point for (arrays,), likewise
    settings: StepSettings
    revision: int  # the model's settings_revision they were bound at


class FusedStep:
    """The one-call step of a batch of envs on one model (what ``EnvCore.step`` runs).

    Args:
        model: The batched model; its arrays, K tables and settings (``dt_max``, ``min_substeps``,
            ``mode``, ``corrections``) are bound at the first call and bound again after any of the
            settings or the tables is set (its ``settings_revision`` changed), so every step uses
            them as :meth:`FishModel.advance` would.
        duration: Control period [s].
        actions: ``(n, 8)`` C-contiguous float64 action buffer; a call with this very array
            takes the entry point, any other array is copied into it first.
        cfg, beats, obs, out, fish, ep, before: The env core's arrays (:data:`STEP_FIELDS`).
        timing: ``(n, 2)`` each env's command delay and period length [s] (:mod:`pectoral_gym.envs.timing`),
            read at every step; ``None``: no delay, periods of ``duration``.
        task_kernel: The task's ``reward_one`` kernel (the task table's row).
        fin_period: With it, every step also writes the observation's fin block (``observe_fins``) of every
            env, with this largest fin-beat period [s] (``tasks.observe_fins``); ``None``: not.

    Attributes:
        parallel: Whether the parallel build runs (``n >= PARALLEL_MIN_ITEMS``); its first binding starts
            numba's threads waiting passively between steps, if no parallel kernel has started them
            before (:func:`pectoral_gym.model.threads.start_passive_threads`).

    Pickles and deep-copies without the binding (compiled code); a copy binds its own arrays.
    """

    def __init__(self, model, duration: float, actions: np.ndarray, cfg, beats, obs, out, fish, ep, before,
                 task_kernel: Callable[..., Any] = tk.reward_one, timing: np.ndarray | None = None,
                 fin_period: float | None = None):
        self.model = model
        self.duration = float(duration)
        self.actions = actions
        self.env_arrays = (cfg, beats, obs, out, fish, ep, before)
        self.everyone = np.ones(actions.shape[0], dtype=np.bool_)
        if timing is None:
            timing = np.zeros((actions.shape[0], 2))
            timing[:, 1] = self.duration
        self.timing = timing
        self.none = np.zeros(actions.shape[0], dtype=np.bool_)
        self.parallel = actions.shape[0] >= PARALLEL_MIN_ITEMS
        self.task_kernel = task_kernel
        if fin_period is not None and not fin_period > 0.0:
            raise ValueError(f"fin_period must be > 0 s or None, got {fin_period}")
        self.fin_period = None if fin_period is None else float(fin_period)
        self._fins_call: Callable[..., Any] | None = None  # the fin block's entry point, for a step with a mask
        self._bound: _Bound | None = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_bound"] = None
        state["_fins_call"] = None
        return state

    @property
    def kernel(self) -> Callable[..., int]:
        """The build this batch runs (a numba dispatcher)."""
        builds = step_builds(self.task_kernel, self.model.averaged)
        return builds.parallel if self.parallel else builds.serial

    def settings(self) -> StepSettings:
        """The model's settings now, with the types the compiled step takes."""
        m = self.model
        return StepSettings(self.duration, float(m.dt_max), float(m.min_substeps), bool(m.averaged), int(m.mode),
                            int(m.corrections))

    def _bind(self) -> _Bound:
        m = self.model
        revision = m.settings_revision  # read first: a change while binding rebinds at the next call
        settings = self.settings()
        arrays = new_step_arrays(self.actions, *self.env_arrays, self.everyone, self.timing, m.state, m.fins,
                                 m.forcing_cache, m.pending, m.integral, m.coef, m.packed_tables, settings,
                                 self.none, self.fin_period or 0.0)
        kernel = self.kernel
        if self.parallel:
            start_passive_threads()  # before the first parallel step: numba's threads sleep between steps
        call = entry_point(kernel, (arrays, self.none, settings))
        own = entry_point(own_builds(self.task_kernel, m.averaged)[self.parallel], (arrays,))
        if self.parallel:
            kernel, call, own = _chunked(kernel), _chunked(call), _chunked(own)
        return _Bound(arrays, kernel, call, own, settings, revision)

    def __call__(self, actions: np.ndarray, skip: np.ndarray | None = None) -> int:
        """Step the envs not in ``skip`` (a bool mask); returns -1, or the first env with a non-finite action.

        With ``fin_period``, a step taken also writes the fin block of every env's observation.

        The arrays and settings are bound once and again whenever the model's ``settings_revision``
        changes (a setting or the K tables set).

        Raises:
            ValueError: If ``actions`` does not have the buffer's shape ``(n, 8)``.
        """
        buffer = self.actions
        if actions is not buffer:
            if np.shape(actions) != buffer.shape:
                raise ValueError(f"actions must have shape {buffer.shape}, got {np.shape(actions)}")
            buffer[...] = actions  # float64, as the kernels read every action entry
        model = self.model
        bound = self._bound
        if bound is None or bound.revision != model.settings_revision:
            bound = self._bound = self._bind()
        if skip is None:  # the one argument the entry point was compiled for; the fin block in the call
            bad = bound.own(bound.arrays)
        else:
            bad = bound.kernel(bound.arrays, np.ascontiguousarray(skip, dtype=np.bool_), bound.settings)
            if bad < 0 and self.fin_period is not None:
                self._observe_fins()
        if bad < 0:
            model.time += self.duration  # as FishModel.advance
        return bad

    def arrays(self) -> StepArrays:
        """The bound :class:`StepArrays` (bound now if the model's settings changed since, or never bound)."""
        bound = self._bound
        if bound is None or bound.revision != self.model.settings_revision:
            bound = self._bound = self._bind()
        return bound.arrays

    def step_buffer(self) -> int:
        """``self(self.actions)``: step the action buffer's actions, no env skipped (the single env's path)."""
        model = self.model
        bound = self._bound
        if bound is None or bound.revision != model.settings_revision:
            bound = self._bound = self._bind()
        bad = bound.own(bound.arrays)
        if bad < 0:
            model.time += self.duration  # as FishModel.advance
        return bad

    def _observe_fins(self) -> None:
        """The observation's fin block of every env (as :func:`step_own` writes it), through its entry point."""
        fins, obs = self.model.fins, self.env_arrays[2]
        call = self._fins_call
        if call is None:  # the arrays' types are fixed (updated in place, never replaced)
            call = self._fins_call = entry_point(tk.observe_fins, (fins, obs, self.fin_period))
        call(fins, obs, self.fin_period)
