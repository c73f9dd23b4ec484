"""The fin half-stroke state machine: each fin's stroke in progress and its commanded pattern.

Free functions compiled with numba over batched arrays (``n`` fish, fin index
0 right, 1 left):

* ``fins``    ``(n, 2, FIN_FIELDS)``: each fin's current half-stroke, fields below.
* ``pending`` ``(n, 2, 4)``: the commanded pattern per fin in ``FinBeat.as_array`` order,
  ``BEAT_BIAS, BEAT_AMPLITUDE, BEAT_PERIOD, BEAT_RATIO`` (rad, rad, s, -), latched at the
  next turning point.

==============  =====  ======  =====================================================================
field           index  unit    meaning
==============  =====  ======  =====================================================================
``ELAPSED``     0      s       time into the current half-stroke
``DURATION``    1      s       duration of the half-stroke (0: finished, latch at the next advance)
``ANGLE_FROM``  2      rad     fin angle at its start (a turning point)
``ANGLE_TO``    3      rad     fin angle at its end (the next turning point)
``POWER``       4      -       1.0 for a power stroke, 0.0 for a recovery stroke
``BIAS``        5      rad     active pattern (latched from ``pending``): stroke centre ``gamma_0``
``AMPLITUDE``   6      rad     half the stroke angle ``gamma_A``
``PERIOD``      7      s       beat period ``T_p``
``RATIO``       8      -       power/recovery speed ratio ``zeta``
``SWEPT``       9      rad^3/s^2  ``int |g'|^3 dt`` over every stroke swept since the reset (both models; the
                               fin's hydrodynamic work is ``(3 k S_p / 4)`` times it, eq. 14,
                               :meth:`pectoral_gym.model.models.FishModel.fin_work`)
==============  =====  ======  =====================================================================

**Parameter-change rule.** A fin latches its commanded parameters only at a
turning point of its stroke (where ``g' = 0``): at the end of the current
half-stroke, or at once if the fin is not moving. The next half-stroke then
runs from the current angle to the new pattern's turning point
(``bias + amplitude`` for a power stroke, ``bias - amplitude`` for recovery)
with the new pattern's stroke duration. The fin angle and rate stay
continuous; with constant parameters the motion is exactly eq. (21). The
averaged model follows the same schedule and switches its averaged forcing
at the same instants (:mod:`pectoral_gym.model.forcing_cache`).

The kernels index the batched arrays directly (no per-fish views or temporary
arrays): views and allocations touch shared reference counts, which serialises
the threads of the parallel kernels. The small ones the integrator calls at
every segment are inlined (``inline="always"``): a compiled call that passes
arrays costs reference-count updates too.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from pectoral_gym.model.dynamics import fin_force_right, stroke_kinematics
from pectoral_gym.model.fast_step import sin_cos_of_angle
from pectoral_gym.model.jit import njit
from pectoral_gym.model.params import FIN_ANGLE_OFFSET, FIN_ANGLE_SCALE, FIN_FORCE_SCALE, Coef

__all__ = [
    "FIN_FIELDS", "ELAPSED", "DURATION", "ANGLE_FROM", "ANGLE_TO", "POWER", "BIAS", "AMPLITUDE", "PERIOD", "RATIO",
    "SWEPT", "swept_cube",
    "BEAT_BIAS", "BEAT_AMPLITUDE", "BEAT_PERIOD", "BEAT_RATIO", "SIDE",
    "command_fins", "fin_angles", "fin_forcing", "idle", "init_fins", "latch",
    "StrokePhase", "stroke_phase", "advance_phase", "phase_forcing", "command_one",
    "actual_angle", "actual_amplitude", "fin_drag_constant",
]

ELAPSED, DURATION, ANGLE_FROM, ANGLE_TO, POWER = 0, 1, 2, 3, 4
BIAS, AMPLITUDE, PERIOD, RATIO = 5, 6, 7, 8
SWEPT = 9
FIN_FIELDS = 10
BEAT_BIAS, BEAT_AMPLITUDE, BEAT_PERIOD, BEAT_RATIO = 0, 1, 2, 3  # a pattern row (pending, FinBeat.as_array)

SIDE = (1.0, -1.0)  # right fin, left fin (mirror image): the sign of its y force and yaw moment


@njit(inline="always")
def latch(fins, pending, i, f):
    """Start the next half-stroke of fin ``f`` of fish ``i`` with its commanded parameters."""
    bias, amp = pending[i, f, BEAT_BIAS], pending[i, f, BEAT_AMPLITUDE]
    period, ratio = pending[i, f, BEAT_PERIOD], pending[i, f, BEAT_RATIO]
    power = 1.0 - fins[i, f, POWER]
    fins[i, f, ANGLE_FROM] = fins[i, f, ANGLE_TO]
    if power > 0.5:
        fins[i, f, ANGLE_TO] = bias + amp
        fins[i, f, DURATION] = period / (ratio + 1.0)  # eq. (21), power stroke
    else:
        fins[i, f, ANGLE_TO] = bias - amp
        fins[i, f, DURATION] = ratio * period / (ratio + 1.0)  # eq. (21), recovery
    fins[i, f, ELAPSED] = 0.0
    fins[i, f, POWER] = power
    fins[i, f, BIAS] = bias
    fins[i, f, AMPLITUDE] = amp
    fins[i, f, PERIOD] = period
    fins[i, f, RATIO] = ratio


@njit(inline="always")
def swept_cube(fins, i, f, seg, fast=False):
    """``int |g'|^3 dt`` [rad^3/s^2] of fin ``f``'s half-stroke in progress over the next ``seg`` s.

    With ``g' = half (pi/d) sin(phi)``, ``phi = pi s / d``: ``|half|^3 (pi/d)^2 [G(phi)]``,
    ``G = -cos + cos^3 / 3`` (``G(pi) - G(0) = 4/3``). Zero for a still fin. ``fast``: the averaged model's
    fast step's ``cos`` (:func:`pectoral_gym.model.fast_step.sin_cos_of_angle`; the phases lie in ``[0, pi]``).
    """
    duration = fins[i, f, DURATION]
    half = 0.5 * (fins[i, f, ANGLE_TO] - fins[i, f, ANGLE_FROM])
    if half == 0.0 or duration <= 0.0:
        return 0.0
    rate = math.pi / duration
    if fast:
        c0 = sin_cos_of_angle(rate * fins[i, f, ELAPSED])[1]
        c1 = sin_cos_of_angle(rate * min(fins[i, f, ELAPSED] + seg, duration))[1]
    else:
        c0 = math.cos(rate * fins[i, f, ELAPSED])
        c1 = math.cos(rate * min(fins[i, f, ELAPSED] + seg, duration))
    return abs(half) ** 3 * rate * rate * ((c0 - c0**3 / 3.0) - (c1 - c1**3 / 3.0))


@njit(inline="always")
def idle(fins, pending, i, f):
    """True for a fin that holds still and is commanded to hold still at the same angle."""
    return (
        fins[i, f, ANGLE_FROM] == fins[i, f, ANGLE_TO]
        and pending[i, f, BEAT_AMPLITUDE] == 0.0
        and pending[i, f, BEAT_BIAS] == fins[i, f, ANGLE_TO]
    )


@njit
def fin_forcing(fins, coef, i, offset):
    """Total blade-element force [N] and moment [N m] of both fins of fish ``i``, ``offset`` s into the segment.

    Eqs. (9)-(18) with each fin's force factor and servo map from the packed coefficients ``coef``
    (:data:`pectoral_gym.model.params.COEF_NAMES`). Direct evaluation at one instant; the full model's
    integrator rotates the phases instead (:class:`StrokePhase`).
    """
    right = stroke_phase(fins, i, 0, 0.0, offset, coef[i, FIN_ANGLE_OFFSET[0]], coef[i, FIN_ANGLE_SCALE[0]])
    left = stroke_phase(fins, i, 1, 0.0, offset, coef[i, FIN_ANGLE_OFFSET[1]], coef[i, FIN_ANGLE_SCALE[1]])
    drag = coef[i, Coef.FIN_DRAG_CONSTANT]
    return phase_forcing(right, left, drag * coef[i, FIN_FORCE_SCALE[0]], drag * coef[i, FIN_FORCE_SCALE[1]],
                         coef[i, Coef.FIN_INERTIA_CONSTANT], coef[i, Coef.FIN_OFFSET])


@njit(inline="always")
def actual_angle(coef, i, f, angle):
    """Fin ``f``'s actual angle [rad] for its commanded ``angle``: ``a_0 + a_1 angle`` (the servo map).

    Exactly ``angle`` for the symmetric fish (offset 0.0, scale 1.0).
    """
    return coef[i, FIN_ANGLE_OFFSET[f]] + coef[i, FIN_ANGLE_SCALE[f]] * angle


@njit(inline="always")
def actual_amplitude(coef, i, f, amplitude):
    """Fin ``f``'s actual amplitude (or signed half-swing) [rad] for a commanded one: ``a_1 amplitude``."""
    return coef[i, FIN_ANGLE_SCALE[f]] * amplitude


@njit(inline="always")
def fin_drag_constant(coef, i, f):
    """Fin ``f``'s drag constant ``k_f = lambda_f k`` [N s^2] (its force factor times eq. 13's ``k``)."""
    return coef[i, Coef.FIN_DRAG_CONSTANT] * coef[i, FIN_FORCE_SCALE[f]]


class StrokePhase(NamedTuple):
    """A fin's half-stroke ``g = mid - half cos(phase)`` (:func:`~pectoral_gym.model.dynamics.stroke_kinematics`).

    The phase ``pi s / d`` grows by the same angle every integrator half-substep, so its cosine and
    sine follow by rotation: two trigonometric calls per fin and segment instead of two per force
    evaluation (the full model's RK4 evaluates the forces twice per substep). Rounding drifts by
    ~1e-16 per rotation and restarts from the exact values at every segment. ``mid`` and ``half`` are the
    fin's actual motion: the commanded half-stroke through the fin's servo map (:func:`stroke_phase`).
    """

    cos: float  # cos(phase) now
    sin: float  # sin(phase) now
    cos_step: float  # of the phase advance per rotation
    sin_step: float
    mid: float  # rad, centre of the stroke
    half: float  # rad, signed half-width
    rate: float  # 1/s, pi / d
    moving: bool  # False: a still fin exerts no force


@njit(inline="always")
def stroke_phase(fins, i, f, step, offset=0.0, angle_offset=0.0, angle_scale=1.0):
    """Fin ``f`` of fish ``i`` ``offset`` s after its elapsed time, rotating by ``step`` s per :func:`advance_phase`.

    ``angle_offset`` [rad] and ``angle_scale`` [-] are the fin's servo map (its actual angle is
    ``angle_offset + angle_scale g`` for the commanded ``g``): the phase describes the actual motion.
    """
    angle_from, angle_to = fins[i, f, ANGLE_FROM], fins[i, f, ANGLE_TO]
    if angle_from == angle_to:
        return StrokePhase(1.0, 0.0, 1.0, 0.0, angle_offset + angle_scale * angle_from, 0.0, 0.0, False)
    rate = math.pi / fins[i, f, DURATION]
    phase = rate * (fins[i, f, ELAPSED] + offset)
    return StrokePhase(math.cos(phase), math.sin(phase), math.cos(rate * step), math.sin(rate * step),
                       angle_offset + angle_scale * (0.5 * (angle_from + angle_to)),
                       angle_scale * (0.5 * (angle_to - angle_from)), rate, True)


@njit(inline="always")
def advance_phase(p: StrokePhase) -> StrokePhase:
    """``p`` one step later (rotation of its phase)."""
    return StrokePhase(p.cos * p.cos_step - p.sin * p.sin_step, p.sin * p.cos_step + p.cos * p.sin_step,
                       p.cos_step, p.sin_step, p.mid, p.half, p.rate, p.moving)


@njit(inline="always")
def phase_forcing(right: StrokePhase, left: StrokePhase, drag_right, drag_left, inertia_constant, fin_offset):
    """:func:`fin_forcing` from both fins' :class:`StrokePhase` (eqs. 9-18), each fin with its drag constant [N s^2]."""
    fx_total = 0.0
    fy_total = 0.0
    tau_total = 0.0
    for f in range(2):
        p = right if f == 0 else left
        if not p.moving:
            continue
        g = p.mid - p.half * p.cos
        gd = p.half * p.rate * p.sin
        gdd = p.half * p.rate * p.rate * p.cos
        fx, fy = fin_force_right(g, gd, gdd, drag_right if f == 0 else drag_left, inertia_constant)
        side = SIDE[f]
        fx_total += fx
        fy_total += side * fy  # left fin mirrors y
        tau_total += side * fin_offset * fx  # eq. (18): tau_R = +C_p f_hx, tau_L = -C_p f_hx
    return fx_total, fy_total, tau_total


@njit(inline="always")
def command_one(i, fins, pending, new, mask):
    """:func:`command_fins` for fish ``i`` alone (a no-op unless ``mask[i]``)."""
    if not mask[i]:
        return
    for f in range(2):
        for j in range(4):
            pending[i, f, j] = new[i, f, j]
        if fins[i, f, ANGLE_FROM] == fins[i, f, ANGLE_TO]:
            fins[i, f, ELAPSED] = fins[i, f, DURATION]
            fins[i, f, POWER] = 0.0


@njit
def command_fins(fins, pending, new, mask):
    """Store new commanded patterns ``new`` ``(n, 2, 4)`` for the fish where ``mask``.

    A fin that is not moving (its stroke starts and ends at the same angle)
    latches at once: its current stroke is marked finished, and it starts with
    a power stroke.
    """
    for i in range(new.shape[0]):
        command_one(i, fins, pending, new, mask)


def init_fins(fins: np.ndarray, pending: np.ndarray, beats: np.ndarray, index: np.ndarray | None = None) -> None:
    """Put the fins of the fish in ``index`` (all if ``None``) at the start of a power stroke of ``beats``.

    ``beats`` has one ``(2, 4)`` row per selected fish.

    The fin sits at ``bias - amplitude`` with zero rate; the first half-stroke
    latches the pattern when the model first advances.
    """
    idx = slice(None) if index is None else index
    b = beats  # one row per selected fish
    fins[idx] = 0.0
    fins[idx, :, ANGLE_TO] = b[..., BEAT_BIAS] - b[..., BEAT_AMPLITUDE]
    fins[idx, :, ANGLE_FROM] = fins[idx, :, ANGLE_TO]
    fins[idx, :, DURATION] = 0.0  # finished: latch at the first advance
    fins[idx, :, POWER] = 0.0  # so the first stroke is a power stroke
    fins[idx, :, BIAS:RATIO + 1] = b
    pending[idx] = b


@njit
def fin_angles(fins):
    """Current fin angles ``(n, 2)`` [rad] and rates [rad/s]."""
    n = fins.shape[0]
    angle = np.empty((n, 2))
    rate = np.empty((n, 2))
    for i in range(n):
        for f in range(2):
            if fins[i, f, DURATION] <= 0.0:
                angle[i, f] = fins[i, f, ANGLE_TO]
                rate[i, f] = 0.0
            else:
                g, gd, _ = stroke_kinematics(
                    fins[i, f, ELAPSED], fins[i, f, DURATION], fins[i, f, ANGLE_FROM], fins[i, f, ANGLE_TO]
                )
                angle[i, f] = g
                rate[i, f] = gd
    return angle, rate
