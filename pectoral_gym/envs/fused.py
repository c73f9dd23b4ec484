"""One compiled call per step of a small batch of fish envs: action check and mapping, model advance, reward.

:class:`~pectoral_gym.envs.core.EnvCore` used to make four compiled calls per
step (map the actions, command the fins, advance the model, observe and score),
each paying numba's dispatch, which types every argument (about 85 ns per array
and 0.8 us for the K-table tuple, timed on an empty kernel with numba 0.68):
several microseconds per step at one fish, as much as the averaged model's own
integration. The step kernel here is those four in one compiled function, built
from the same kernels, in the same order:

1. ``tasks._first_non_finite``: a non-finite action of an env not in ``skip``
   stops the step before anything is written (its index is returned);
2. ``tasks._apply_keep_one`` per env: keep the velocity integrals, map the
   action to fin patterns, write the last action and the energy term;
3. ``strokes.command_fins`` for every fish (``FishModel.command_array``);
4. ``stepping``'s serial advance loop (``FishModel.advance`` for fewer than
   ``PARALLEL_MIN_ITEMS`` fish);
5. ``tasks._reward_mean_one`` per env: move the reference, observation, reward
   terms, flags, mean velocities over the control period.

The results are bit for bit those of the separate calls (``tests/test_fused_step.py``
checks them against the separate kernels, and against ``model.command`` + ``model.advance``
and the documented reward formulas).
Batches of ``PARALLEL_MIN_ITEMS`` envs or more keep the parallel kernels.

The arrays of one core are bound once into a :class:`StepArrays` (a numba
structref that holds them, not copies), so a step passes one object, the skip
mask and the model's scalar settings. :func:`bind` also looks up the compiled
entry point of that exact signature, which skips numba's argument typing (done
in Python for a structref, about 1 us a call); it is used only with the bound
arrays and the core's own all-false mask, the types it was compiled for.

This kernel inlines code from many modules, among them ``stepping.py``; like every kernel
it is compiled with :func:`pectoral_gym._jit.njit`, whose disk cache is keyed on all the
sources it compiles from, so an edit of any of them compiles it afresh.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numba as nb
import numpy as np
from numba.core import types
from numba.experimental import structref

from pectoral_gym import stepping
from pectoral_gym._jit import njit
from pectoral_gym.envs import tasks as tk
from pectoral_gym.strokes import command_fins

__all__ = ["STEP_FIELDS", "BoundStep", "FusedStep", "StepArrays", "bind", "step_kernel"]

@structref.register
class StepArraysType(types.StructRef):
    """numba type of :class:`StepArrays` (its fields' array types)."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class StepArrays(structref.StructRefProxy):
    """The arrays one env core steps, held by reference for the compiled step (fields: :data:`STEP_FIELDS`)."""


#: The fields of :class:`StepArrays`: the env core's arrays (``actions`` its action buffer,
#: ``before`` its velocity integrals before the step, ``everyone`` an all-true mask), then the
#: model's arrays and its K tables as :func:`pectoral_gym.stepping.advance` takes them.
STEP_FIELDS = ("actions", "cfg", "beats", "obs", "out", "fish", "ep", "before", "everyone",
               "state", "fins", "cache", "pending", "integral", "coef", "tables")
structref.define_proxy(StepArrays, StepArraysType, list(STEP_FIELDS))


@njit
def new_step_arrays(actions, cfg, beats, obs, out, fish, ep, before, everyone, state, fins, cache, pending, integral,
                    coef, tables):
    """A :class:`StepArrays` of these arrays; compiled and cached (``StepArrays(...)`` compiles anew per process)."""
    return StepArrays(actions, cfg, beats, obs, out, fish, ep, before, everyone, state, fins, cache, pending,
                      integral, coef, tables)


@njit
def _step_bound(a, skip, duration, dt_max, min_substeps, averaged, mode, corrections):
    """The step of :func:`step_kernel`."""
    bad = tk._first_non_finite(a.actions, skip)
    if bad >= 0:
        return bad
    n = a.actions.shape[0]
    for i in range(n):
        tk._apply_keep_one(i, a.actions, skip, a.cfg, a.beats, a.obs, a.out, a.fish, a.integral, a.before)
    command_fins(a.fins, a.pending, a.beats, a.everyone)
    # the loop FishModel.advance runs below PARALLEL_MIN_ITEMS fish (stepping.advance)
    stepping._SERIAL(a.state, a.fins, a.cache, a.pending, a.integral, a.coef, duration, dt_max, min_substeps,
                     averaged, mode, corrections, a.tables)
    for i in range(n):
        tk._reward_mean_one(i, a.state, skip, a.cfg, a.ep, a.fish, a.obs, a.out, a.integral, a.before)
    return -1


def step_kernel() -> Callable[..., Any]:
    """The compiled step (a numba dispatcher).

    ``step_kernel()(arrays, skip, duration, dt_max, min_substeps, averaged, mode, corrections)``
    steps the envs of ``arrays`` (a :class:`StepArrays`) except those where ``skip``, by
    ``duration`` seconds, with the model settings as :func:`pectoral_gym.stepping.advance`
    takes them (``min_substeps`` a float). Returns -1, or the index of the first env not in
    ``skip`` whose action is not finite (then nothing has been written).
    """
    return _step_bound


class BoundStep(NamedTuple):
    """A batch's arrays bound for the compiled step, and the fastest way to call it.

    Attributes:
        arrays: The :class:`StepArrays`.
        call: ``call(arrays, skip, duration, dt_max, min_substeps, averaged, mode, corrections)``:
            the compiled entry point of exactly these types (``skip`` a C-contiguous bool array
            of the batch size; it converts the scalars as ``float, float, float, bool, int, bool``
            do), or the dispatcher behind those conversions if numba does not expose it.
        kernel: The dispatcher (:func:`step_kernel`), for any other ``skip``.
        tables: The K-table tuple bound in ``arrays`` (rebind when the model's changes).
    """

    arrays: StepArrays
    call: Callable[..., int]
    kernel: Callable[..., int]
    tables: tuple


def bind(arrays: StepArrays, tables: tuple, example: tuple) -> BoundStep:
    """Look up the entry point for ``arrays`` (holding ``tables``) and the types of ``example`` (skip, scalars).

    The kernel is compiled for them, or loaded from the disk cache, here.
    """
    kernel = step_kernel()
    signature = tuple(nb.typeof(x) for x in (arrays, *example))
    kernel.compile(signature)
    try:  # numba's compiled entry point of this signature: no argument typing per call
        call = kernel.overloads[signature].entry_point
    except (AttributeError, KeyError):  # pragma: no cover - other numba versions: the dispatcher, same types

        def call(arrays, skip, duration, dt_max, min_substeps, averaged, mode, corrections):
            return kernel(arrays, skip, float(duration), float(dt_max), float(min_substeps), bool(averaged),
                          int(mode), int(corrections))
    return BoundStep(arrays, call, kernel, tables)


class FusedStep:
    """The one-call step of a batch of envs on one model (what ``EnvCore.step`` runs below 64 envs).

    Args:
        model: The batched model; its arrays are bound at the first call, its settings
            (``dt_max``, ``min_substeps``, ``mode``, ``corrections``) read at every call and
            its K tables rebound when they change, as :meth:`FishModel.advance` reads them.
        duration: Control period [s].
        actions: ``(n, 8)`` C-contiguous float64 action buffer; a call with this very array
            takes the entry point, any other array is copied into it first.
        cfg, beats, obs, out, fish, ep, before: The env core's arrays (:data:`STEP_FIELDS`).

    Pickles and deep-copies without the binding (compiled code); a copy binds its own arrays.
    """

    def __init__(self, model, duration: float, actions: np.ndarray, cfg, beats, obs, out, fish, ep, before):
        self.model = model
        self.duration = float(duration)
        self.actions = actions
        self.env_arrays = (cfg, beats, obs, out, fish, ep, before)
        self.everyone = np.ones(actions.shape[0], dtype=np.bool_)
        self.none = np.zeros(actions.shape[0], dtype=np.bool_)
        self._bound: BoundStep | None = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_bound"] = None
        return state

    def _bind(self) -> BoundStep:
        m = self.model
        tables = m._packed_tables  # the tuple FishModel.advance passes (ktables.as_tables)
        arrays = new_step_arrays(self.actions, *self.env_arrays, self.everyone, m.state, m.fins, m.forcing_cache,
                                 m.pending, m.integral, m.coef, tables)
        return bind(arrays, tables, (self.none, self.duration, float(m.dt_max), float(m.min_substeps), bool(m.averaged),
                             int(m.mode), int(m.corrections)))

    def __call__(self, actions: np.ndarray, skip: np.ndarray | None = None) -> int:
        """Step the envs not in ``skip`` (a bool mask); returns -1, or the first env with a non-finite action.

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
        if bound is None or bound.tables is not model._packed_tables:
            bound = self._bound = self._bind()
        if skip is None:  # the types the entry point was compiled for
            bad = bound.call(bound.arrays, self.none, self.duration, model.dt_max, model.min_substeps,
                             model.averaged, model.mode, model.corrections)
        else:
            bad = bound.kernel(bound.arrays, skip, self.duration, float(model.dt_max), float(model.min_substeps),
                               bool(model.averaged), int(model.mode), int(model.corrections))
        if bad < 0:
            model.time += self.duration  # as FishModel.advance
        return bad
