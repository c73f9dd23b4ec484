"""The averaged model's per-fin forcing cache: scaled averaged forcing and yaw-oscillation phasor.

The averaged model (eq. 25) holds each fin's averaged force constant over a
half-stroke. Evaluating it (the K polynomial and splines, the Bessel average)
costs more than a whole RK4 step, so it is computed when a fin latches a
pattern and kept, with the pattern it belongs to, until the pattern changes:

* ``cache`` ``(n, 2, CACHE_FIELDS)``, one row per fish and fin (0 right, 1 left):

=================  =====  ======  ==================================================================
field              index  unit    meaning
=================  =====  ======  ==================================================================
``KEY_BIAS``       0      rad     commanded pattern the row was computed for: bias ``gamma_0``
``KEY_AMPLITUDE``  1      rad     amplitude ``gamma_A``
``KEY_PERIOD``     2      s       period ``T_p``
``KEY_RATIO``      3      -       ratio ``zeta``
``AVG_FX``         4      N       ``K_fx f_hx_avg`` (eq. 25) of the actual pattern (servo map, force factor)
``AVG_FY``         5      N       ``K_fy f_hy_avg`` (or ``K_fy base``), signed by side
``AVG_TAU``        6      N m     ``K_m tau_avg``, signed by side
``OSC_COS``        7      rad/s   phasor ``A cos(phi)`` of the yaw-rate oscillation, signed by side
``OSC_SIN``        8      rad/s   ``A sin(phi)``
``CACHED``         9      -       1.0 when the row is valid for the key (0: recompute at the next latch)
``PREV_BIAS``      10     rad     pattern of the fin's last finished power stroke (``transitions``,
``PREV_AMPLITUDE`` 11     rad     ``docs/model.md`` section 3.7): bias, amplitude, period, ratio;
``PREV_PERIOD``    12     s       zero after :func:`clear`
``PREV_RATIO``     13     -
``TR_FX``          14     N       the half-stroke in progress's transitional forcing (``transitions``,
``TR_FY``          15     N       ``docs/model.md`` section 3.7; ``stroke_corrections._transition``),
``TR_TAU``         16     N m     signed by side; set when the fin latches, zero after :func:`clear`
``OFF_FX``         17     N s     the beat-mean ripple offset delivered so far (``ripple_offsets``,
``OFF_FY``         18     N s     ``docs/model.md`` 3.8: ``M`` of the fin's latched pattern,
``OFF_TAU``        19     N m s   :func:`pectoral_gym.model.averaging.ripple_offset`), signed by side; zero
                                  after :func:`clear`
``OSC_EXCESS``     20     -       the half-stroke in progress's yaw-oscillation gain minus one
                                  (``transitions``, ``docs/model.md`` 3.9,
                                  :func:`pectoral_gym.model.ripple.transitional_oscillation_gain`);
                                  set when the fin latches, zero on regular half-strokes
=================  =====  ======  ==================================================================

The row depends on the fish's coefficients too: :func:`invalidate` after
changing them. :func:`clear` zeroes rows (no forcing until the next latch), as
at a reset: a fin that stays at rest never latches.
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.model.averaging import scaled_forcing
from pectoral_gym.model.fast_step import sin_cos_of_angle
from pectoral_gym.model.jit import njit
from pectoral_gym.model.ktables import pattern_values
from pectoral_gym.model.params import FIN_FORCE_SCALE
from pectoral_gym.model.strokes import ANGLE_FROM, ANGLE_TO, ELAPSED, PERIOD, POWER, RATIO, SIDE, actual_angle
from pectoral_gym.model.strokes import actual_amplitude as actual_amplitude_of

__all__ = [
    "CACHE_FIELDS", "KEY_BIAS", "KEY_AMPLITUDE", "KEY_PERIOD", "KEY_RATIO",
    "AVG_FX", "AVG_FY", "AVG_TAU", "OSC_COS", "OSC_SIN", "CACHED",
    "PREV_BIAS", "PREV_AMPLITUDE", "PREV_PERIOD", "PREV_RATIO", "TR_FX", "TR_FY", "TR_TAU",
    "OFF_FX", "OFF_FY", "OFF_TAU", "OSC_EXCESS",
    "clear", "invalidate", "refresh", "yaw_oscillation",
]

KEY_BIAS, KEY_AMPLITUDE, KEY_PERIOD, KEY_RATIO = 0, 1, 2, 3
AVG_FX, AVG_FY, AVG_TAU = 4, 5, 6
OSC_COS, OSC_SIN = 7, 8
CACHED = 9
PREV_BIAS, PREV_AMPLITUDE, PREV_PERIOD, PREV_RATIO = 10, 11, 12, 13
TR_FX, TR_FY, TR_TAU = 14, 15, 16
OFF_FX, OFF_FY, OFF_TAU = TR_TAU + 1, TR_TAU + 2, TR_TAU + 3
OSC_EXCESS = OFF_TAU + 1
CACHE_FIELDS = OSC_EXCESS + 1


def invalidate(cache: np.ndarray, index: np.ndarray | slice | None = None) -> None:
    """Mark the rows of the fish in ``index`` (all if ``None``) stale, e.g. after their coefficients changed."""
    cache[slice(None) if index is None else index, :, CACHED] = 0.0


def clear(cache: np.ndarray, index: np.ndarray | slice | None = None) -> None:
    """Zero the rows of the fish in ``index`` (all if ``None``): no forcing until their fins latch."""
    cache[slice(None) if index is None else index] = 0.0


@njit(inline="always")
def refresh(cache, i, f, bias, amplitude, period, ratio, coef, mode, tables, fast=False):
    """Make fin ``f`` of fish ``i``'s row hold the forcing of pattern ``(bias, amplitude, period, ratio)``.

    Nothing is computed when the row already holds it (the same pattern as the last half-stroke).
    ``fast``: the averaged model's fast step (:func:`pectoral_gym.model.averaging.scaled_forcing`).
    """
    if (cache[i, f, CACHED] == 1.0 and cache[i, f, KEY_BIAS] == bias and cache[i, f, KEY_AMPLITUDE] == amplitude
            and cache[i, f, KEY_PERIOD] == period and cache[i, f, KEY_RATIO] == ratio):
        return
    cache[i, f, KEY_BIAS] = bias
    cache[i, f, KEY_AMPLITUDE] = amplitude
    cache[i, f, KEY_PERIOD] = period
    cache[i, f, KEY_RATIO] = ratio
    # K, the averages and the oscillation belong to the pattern the fin actually beats (its servo map)
    actual_bias, actual_amplitude = actual_angle(coef, i, f, bias), actual_amplitude_of(coef, i, f, amplitude)
    kx, ky, km, pc, ps = pattern_values(actual_bias, actual_amplitude, period, ratio, tables)
    fx, fy, tau = scaled_forcing(actual_bias, actual_amplitude, period, ratio, SIDE[f], coef[i], mode, kx, ky, km,
                                 tables.base_sway, fast)
    cache[i, f, AVG_FX] = fx
    cache[i, f, AVG_FY] = fy
    cache[i, f, AVG_TAU] = tau
    # the left fin's yaw oscillation is the mirror image; a fin's in-beat moment, and with it the
    # oscillation it drives, scales with its force factor (docs/model.md section 2, "Fins that differ")
    force_scale = coef[i, FIN_FORCE_SCALE[f]]
    cache[i, f, OSC_COS] = SIDE[f] * pc * force_scale
    cache[i, f, OSC_SIN] = SIDE[f] * ps * force_scale
    cache[i, f, CACHED] = 1.0


@njit(inline="always")
def yaw_oscillation(fins, cache, i, offset, idle0, idle1, fast=False):
    """Amplitude [rad/s] of the yaw-rate oscillation both fins drive, ``offset`` s into the segment.

    Each fin's oscillation is ``Re(G P e^{i theta})`` with its phasor ``P``, the gain ``G`` of
    its half-stroke in progress (``OSC_EXCESS``, 1 on regular half-strokes) and its beat phase
    ``theta = 2 pi t / T_p`` (``t`` from the start of its power stroke, read from the fin state
    of :mod:`pectoral_gym.model.strokes`); the two add
    as phasors. Fins beating in phase with the same pattern cancel (straight
    swimming has no yaw oscillation); fins with different periods drift
    through all relative phases. ``fast``: the averaged model's fast step's ``sin, cos`` of the phase (in
    ``[0, 2 pi]``: :func:`pectoral_gym.model.fast_step.sin_cos_of_angle` of its half, doubled).
    """
    re = 0.0
    im = 0.0
    for f in range(2):
        if (idle0 if f == 0 else idle1) or fins[i, f, ANGLE_FROM] == fins[i, f, ANGLE_TO]:
            continue
        if cache[i, f, OSC_COS] == 0.0 and cache[i, f, OSC_SIN] == 0.0:
            continue  # no yaw-oscillation data (or no stroke): skip the trigonometry
        theta = _beat_phase(fins, i, f, offset)
        gain = 1.0 + cache[i, f, OSC_EXCESS]  # a transitional half-stroke's (docs/model.md 3.9)
        if fast:
            sin_half, cos_half = sin_cos_of_angle(0.5 * theta)
            c, s = gain * (cos_half * cos_half - sin_half * sin_half), gain * (2.0 * sin_half * cos_half)
        else:
            c, s = gain * math.cos(theta), gain * math.sin(theta)
        re += cache[i, f, OSC_COS] * c - cache[i, f, OSC_SIN] * s
        im += cache[i, f, OSC_COS] * s + cache[i, f, OSC_SIN] * c
    return math.sqrt(re * re + im * im)


@njit(inline="always")
def _beat_phase(fins, i, f, offset):
    """Beat phase ``2 pi t / T_p`` of fin ``f``, ``t`` from the start of its power stroke, ``offset`` s ahead."""
    period = fins[i, f, PERIOD]
    t = fins[i, f, ELAPSED] + offset
    if fins[i, f, POWER] < 0.5:
        t += period / (fins[i, f, RATIO] + 1.0)  # recovery follows the power stroke
    return 2.0 * math.pi * t / period
