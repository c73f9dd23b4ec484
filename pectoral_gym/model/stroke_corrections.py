"""The averaged model's corrections of a half-stroke, evaluated once where a fin starts it (compiled).

When a fin starts a half-stroke it latches its commanded pattern
(:func:`pectoral_gym.model.strokes.latch`); the averaged model then brings its forcing cache
(:mod:`pectoral_gym.model.forcing_cache`) up to date and, with its corrections on
(:func:`corrections`), adds what the cycle averages leave out, constant over the half-stroke:

* :data:`TRANSITIONS`: the forcing of a transitional half-stroke beyond its pattern's regular
  one (``docs/model.md`` 3.7, :func:`_transition`) and its yaw-oscillation gain (3.9,
  :func:`_oscillation_gain`);
* :data:`RIPPLE_OFFSETS`: the change of the fin's beat-mean ripple offset, spread over the
  half-stroke (3.8, :func:`_ripple_offset_change`).

All are zero at periodic steady state. :func:`start_half_stroke` is what the integrator
(:func:`pectoral_gym.model.stepping.advance_one`) calls at every stroke boundary; the CasADi
twins of 3.7 and 3.8 are in :mod:`pectoral_gym.model.symbolic_corrections`.
"""

from __future__ import annotations

from pectoral_gym.model import forcing_cache as fc
from pectoral_gym.model import strokes as st
from pectoral_gym.model.averaging import half_stroke_mean_force, power_stroke_excess, ripple_offset
from pectoral_gym.model.jit import njit
from pectoral_gym.model.params import Coef
from pectoral_gym.model.ripple import transitional_oscillation_gain
from pectoral_gym.model.strokes import AMPLITUDE, BIAS, DURATION, PERIOD, RATIO, latch

__all__ = ["FAST_STEP", "RIPPLE_OFFSETS", "TRANSITIONS", "corrections", "start_half_stroke"]

#: Bits of the averaged model's ``corrections`` (:func:`corrections`): the transitional half-strokes
#: (``docs/model.md`` 3.7, with their yaw-oscillation gain, 3.9) and the beat-mean ripple offset (3.8).
TRANSITIONS, RIPPLE_OFFSETS = 1, 2
#: A bit of the same argument that is no correction: the averaged model's fast step
#: (:mod:`pectoral_gym.model.fast_step`), carried with the corrections so that every kernel that takes
#: them (the model's and the envs') takes it too.
FAST_STEP = 4


def corrections(transitions: bool, ripple_offsets: bool, fast_step: bool = False) -> int:
    """The ``corrections`` argument of :func:`pectoral_gym.model.stepping.advance` from the averaged model's options."""
    return ((TRANSITIONS if transitions else 0) | (RIPPLE_OFFSETS if ripple_offsets else 0)
            | (FAST_STEP if fast_step else 0))


@njit(inline="always")
def start_half_stroke(fins, cache, pending, i, f, coef, averaged, mode, tables, corrections):
    """Latch fin ``f``'s commanded pattern; the averaged model also brings its forcing cache up to date.

    The corrections (:data:`TRANSITIONS`: :func:`_transition` and the half-stroke's yaw-oscillation
    gain, :func:`_oscillation_gain`; :data:`RIPPLE_OFFSETS`: the change of the beat-mean ripple
    offset, spread over the half-stroke) are constant over the half-stroke, so they are evaluated
    here, once, and kept in the cache (``TR_*``, ``OSC_EXCESS``).
    """
    if averaged and fins[i, f, st.POWER] > 0.5:  # a power stroke ends: keep its pattern (_transition)
        cache[i, f, fc.PREV_BIAS] = fins[i, f, BIAS]
        cache[i, f, fc.PREV_AMPLITUDE] = fins[i, f, AMPLITUDE]
        cache[i, f, fc.PREV_PERIOD] = fins[i, f, PERIOD]
        cache[i, f, fc.PREV_RATIO] = fins[i, f, RATIO]
    latch(fins, pending, i, f)
    if averaged:
        fast = (corrections & FAST_STEP) != 0
        fc.refresh(cache, i, f, fins[i, f, BIAS], fins[i, f, AMPLITUDE], fins[i, f, PERIOD], fins[i, f, RATIO],
                   coef, mode, tables, fast)
        if corrections & (TRANSITIONS | RIPPLE_OFFSETS):
            dfx = dfy = dtau = 0.0
            if corrections & TRANSITIONS:
                dfx, dfy, dtau = _transition(fins, cache, coef, i, f, fast)
                cache[i, f, fc.OSC_EXCESS] = _oscillation_gain(fins, i, f, coef, fast) - 1.0
            if corrections & RIPPLE_OFFSETS:
                ox, oy, ot = _ripple_offset_change(fins, cache, coef, i, f, fast)
                duration = fins[i, f, DURATION]
                dfx, dfy, dtau = dfx + ox / duration, dfy + oy / duration, dtau + ot / duration
            cache[i, f, fc.TR_FX] = dfx
            cache[i, f, fc.TR_FY] = dfy
            cache[i, f, fc.TR_TAU] = dtau


@njit(inline="always")
def _oscillation_gain(fins, i, f, coef, fast):
    """Yaw-oscillation gain of fin ``f``'s latched half-stroke (``docs/model.md`` 3.9; 1 on a regular one)."""
    return transitional_oscillation_gain(st.actual_angle(coef, i, f, fins[i, f, st.ANGLE_FROM]),
                                         st.actual_angle(coef, i, f, fins[i, f, st.ANGLE_TO]), fins[i, f, DURATION],
                                         fins[i, f, st.POWER] > 0.5, st.actual_angle(coef, i, f, fins[i, f, BIAS]),
                                         st.actual_amplitude(coef, i, f, fins[i, f, AMPLITUDE]),
                                         fins[i, f, PERIOD], fins[i, f, RATIO], st.fin_drag_constant(coef, i, f),
                                         coef[i, Coef.FIN_INERTIA_CONSTANT], fast)


@njit(inline="always")
def _ripple_offset_change(fins, cache, coef, i, f, fast):
    """Impulse [N s, N s, N m s] that moves fin ``f``'s delivered ripple offset to its latched pattern's.

    ``docs/model.md`` section 3.8: the averaged state is the beat mean of the full model's,
    which runs ahead of its cycle-start value by ``M / m`` (:func:`ripple_offset`); a fin that
    starts a pattern, changes it or parks moves that offset from the old pattern's ``M`` to the
    new one's. Zero while the pattern is kept.
    """
    mx, my = ripple_offset(st.actual_angle(coef, i, f, fins[i, f, BIAS]),
                           st.actual_amplitude(coef, i, f, fins[i, f, AMPLITUDE]), fins[i, f, PERIOD],
                           fins[i, f, RATIO], st.fin_drag_constant(coef, i, f), fast)
    fin_offset = coef[i, Coef.FIN_OFFSET]
    side = st.SIDE[f]
    mx, my, mt = mx, side * my, side * fin_offset * mx  # eq. (18), left fin mirrored
    ox, oy, ot = mx - cache[i, f, fc.OFF_FX], my - cache[i, f, fc.OFF_FY], mt - cache[i, f, fc.OFF_TAU]
    cache[i, f, fc.OFF_FX] = mx
    cache[i, f, fc.OFF_FY] = my
    cache[i, f, fc.OFF_TAU] = mt
    return ox, oy, ot


@njit(inline="always")
def _transition(fins, cache, coef, i, f, fast):
    """Averaged model: forcing of fin ``f``'s half-stroke in progress beyond its pattern's regular one.

    Two parts (``docs/model.md`` section 3.7), both zero at periodic steady state:

    * the exact mean of the half-stroke actually swept (from ``ANGLE_FROM``) minus that of
      the latched pattern's regular half-stroke (from its other turning point), both ending
      at ``ANGLE_TO`` in ``DURATION`` s;
    * on a recovery stroke after a power stroke of another pattern: the impulse offset that
      power stroke left, ``X(previous) - X(latched)`` (:func:`power_stroke_excess`), spread
      over the recovery stroke.

    The fin state holds commanded angles and patterns (compared as they are); the forces are those of
    the fin's actual motion (its servo map) with its own ``k``.
    """
    drag_constant = st.fin_drag_constant(coef, i, f)
    fin_offset = coef[i, Coef.FIN_OFFSET]
    duration = fins[i, f, DURATION]
    if duration <= 0.0:
        return 0.0, 0.0, 0.0
    power = fins[i, f, st.POWER] > 0.5
    bias, amp = fins[i, f, BIAS], fins[i, f, AMPLITUDE]
    start = bias - amp if power else bias + amp
    angle_from = fins[i, f, st.ANGLE_FROM]
    dx = 0.0
    dy = 0.0
    if angle_from != start:
        angle_to = st.actual_angle(coef, i, f, fins[i, f, st.ANGLE_TO])
        ax, ay = half_stroke_mean_force(st.actual_angle(coef, i, f, angle_from), angle_to, duration, drag_constant,
                                        fast)
        rx, ry = half_stroke_mean_force(st.actual_angle(coef, i, f, start), angle_to, duration, drag_constant, fast)
        dx, dy = ax - rx, ay - ry
    if not power and (cache[i, f, fc.PREV_BIAS] != bias or cache[i, f, fc.PREV_AMPLITUDE] != amp
                      or cache[i, f, fc.PREV_PERIOD] != fins[i, f, PERIOD]
                      or cache[i, f, fc.PREV_RATIO] != fins[i, f, RATIO]):
        px, py = power_stroke_excess(st.actual_angle(coef, i, f, cache[i, f, fc.PREV_BIAS]),
                                     st.actual_amplitude(coef, i, f, cache[i, f, fc.PREV_AMPLITUDE]),
                                     cache[i, f, fc.PREV_PERIOD], cache[i, f, fc.PREV_RATIO], drag_constant, fast)
        qx, qy = power_stroke_excess(st.actual_angle(coef, i, f, bias), st.actual_amplitude(coef, i, f, amp),
                                     fins[i, f, PERIOD], fins[i, f, RATIO], drag_constant, fast)
        dx += (px - qx) / duration
        dy += (py - qy) / duration
    side = st.SIDE[f]
    return dx, side * dy, side * fin_offset * dx  # eq. (18), left fin mirrored
