"""Many consecutive advances of a model in one compiled call: the fins' replays and the liveness check's paths.

A replay of the fins (:class:`pectoral_gym.model.finreplay.FinReplay`) advances its one-fish model by one firmware
tick (:data:`pectoral_gym.model.finrules.CHUNK`) at a time, and the liveness check's predictions advance their
fish segment by segment, setting the fins from a snapshot between segments. Each advance from Python costs a
compiled call and its wrappers, several times the arithmetic of a short segment. The kernels here run a whole
sequence of such advances in one call: the same per-fish kernel
(:data:`pectoral_gym.model.stepping.ADVANCE_ONE`) with the same arguments in the same order, so each fish's floats
are, bit for bit, those of the advances made one by one from Python (numba compiles without fast-math: no
operation is reordered or fused).

* :func:`run_schedule`: each fish advanced from a start through snapshots of the fins to given times, its fins and
  commanded patterns set from each snapshot (and its forcing cache marked stale,
  :func:`pectoral_gym.model.forcing_cache.invalidate`) before the advances up to the next one, its pose recorded
  at each time.
* :func:`run_quiet_ticks`: fish 0 advanced tick by tick towards a time, stopping at the first tick whose fin
  fields ``DURATION`` to ``RATIO`` differ from those at the call's start by a bit (a turning point, where the
  firmware's rules may hand over something new): the caller runs the rules there.
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.model import forcing_cache, stepping, strokes
from pectoral_gym.model.jit import kernel_variant, njit

__all__ = ["run_quiet_ticks", "run_schedule"]

AVERAGED = True  # the model of a build (kernel_variant binds it): a constant to numba
ADVANCE = stepping.advance_averaged_one  # the per-fish kernel of that model (kernel_variant binds it)


def _run_schedule(state, fins, cache, pending, integral, coef, snap_times, snap_fins, snap_pending, t_c, times, out,
                  dt_max, min_substeps, mode, corrections, packed_tables):
    """Advance every fish from ``t_c`` through the snapshots to each of ``times`` [s]; poses into ``out``.

    ``snap_times`` ``(K,)`` [s], increasing, the first at or before ``t_c``; ``snap_fins`` ``(K, rows, 2,
    FIN_FIELDS)`` and ``snap_pending`` ``(K, rows, 2, 4)``: the snapshots, each row the fins of ``n // rows``
    consecutive fish. ``times`` ``(T,)`` increase; ``out`` ``(T, n, 3)`` gets ``(X, Y, psi)`` at each. Each fish
    has its fins set from snapshot ``k`` (its forcing cache marked stale), then is advanced to each time up to the
    next snapshot's and to that snapshot; the lengths are ``max(to - now, 0)``, ``now`` the later of the two, as
    a loop in Python computes them. Returns the summed length of one fish's advances [s] (a model's clock).
    """
    n = state.shape[0]
    per = n // snap_fins.shape[1]
    count = snap_times.shape[0]
    clock = 0.0
    for i in range(n):
        row = i // per
        now, taken, clock = t_c, 0, 0.0
        for k in range(count):
            fins[i, :, :] = snap_fins[k, row]
            pending[i, :, :] = snap_pending[k, row]
            cache[i, 0, forcing_cache.CACHED] = 0.0
            cache[i, 1, forcing_cache.CACHED] = 0.0
            until = snap_times[k + 1] if k + 1 < count else np.inf
            while taken < times.shape[0] and times[taken] <= until:
                duration = _later(times[taken] - now, 0.0)
                ADVANCE(i, state, fins, cache, pending, integral, coef, duration, dt_max, min_substeps, AVERAGED,
                        mode, corrections, packed_tables)
                clock += duration
                now = _later(times[taken], now)
                out[taken, i, 0] = state[i, 0]
                out[taken, i, 1] = state[i, 1]
                out[taken, i, 2] = state[i, 2]
                taken += 1
            if taken == times.shape[0]:
                break
            duration = _later(until - now, 0.0)
            ADVANCE(i, state, fins, cache, pending, integral, coef, duration, dt_max, min_substeps, AVERAGED, mode,
                    corrections, packed_tables)
            clock += duration
            now = _later(until, now)
    return clock


@njit(inline="always")
def _later(a, b):
    """Python's ``max(a, b)`` of two floats: ``b`` only if ``b > a``."""
    return b if b > a else a


def _run_quiet_ticks(state, fins, cache, pending, integral, coef, time, target, chunk, dt_max, min_substeps, mode,
                     corrections, packed_tables):
    """Advance fish 0 from ``time`` towards ``target`` [s] by ticks of at most ``chunk`` [s]; returns the new time.

    The first tick is always advanced; each later one only while the fin fields ``DURATION`` to ``RATIO`` hold the
    bits they held at the start (a value and its sign equal; a nan always differs). The ticks' lengths and the
    clock are :func:`pectoral_gym.model.finrules.advance_with_firmware`'s: ``min(chunk, target - time)``, summed.
    """
    first, last = strokes.DURATION, strokes.RATIO + 1
    watch = fins[0, :, first:last].copy()
    ticks = 0
    while time < target:
        if ticks > 0:
            for f in range(2):
                for q in range(last - first):
                    a, b = fins[0, f, first + q], watch[f, q]
                    if not a == b or math.copysign(1.0, a) != math.copysign(1.0, b):
                        return time
        duration = min(chunk, target - time)
        ADVANCE(0, state, fins, cache, pending, integral, coef, duration, dt_max, min_substeps, AVERAGED, mode,
                corrections, packed_tables)
        time += duration
        ticks += 1
    return time


_SCHEDULE = {averaged: kernel_variant(_run_schedule, f"run_schedule_{kind}",
                                      {"AVERAGED": averaged, "ADVANCE": stepping.ADVANCE_ONE[averaged]})
             for averaged, kind in ((True, "averaged"), (False, "full"))}
_QUIET_TICKS = {averaged: kernel_variant(_run_quiet_ticks, f"run_quiet_ticks_{kind}",
                                         {"AVERAGED": averaged, "ADVANCE": stepping.ADVANCE_ONE[averaged]})
                for averaged, kind in ((True, "averaged"), (False, "full"))}


def run_schedule(model, snap_times: np.ndarray, snap_fins: np.ndarray, snap_pending: np.ndarray, t_c: float,
                 times: np.ndarray) -> np.ndarray:
    """Advance ``model``'s fish from ``t_c`` [s] through the snapshots to ``times`` (:func:`_run_schedule`).

    Returns the poses ``(len(times), n, 3)``. ``model`` (a :class:`~pectoral_gym.model.models.FishModel`) ends as
    the advances one by one leave it, its :attr:`time` too (from 0). The arrays are ``float64``, C-contiguous.
    """
    out = np.empty((len(times), model.n, 3))
    model.time = _SCHEDULE[bool(model.averaged)](
        model.state, model.fins, model.forcing_cache, model.pending, model.integral, model.coef, snap_times,
        snap_fins, snap_pending, float(t_c), times, out, float(model.dt_max), float(model.min_substeps),
        int(model.mode), int(model.corrections), model.packed_tables)
    return out


def run_quiet_ticks(model, target: float, chunk: float) -> None:
    """Advance fish 0 of ``model`` tick by tick towards ``target`` [s] while its fins' patterns hold.

    See :func:`_run_quiet_ticks`.

    At least one tick is advanced if ``model.time < target``; :attr:`model.time` is the new time.
    """
    model.time = _QUIET_TICKS[bool(model.averaged)](
        model.state, model.fins, model.forcing_cache, model.pending, model.integral, model.coef, float(model.time),
        float(target), float(chunk), float(model.dt_max), float(model.min_substeps), int(model.mode),
        int(model.corrections), model.packed_tables)
