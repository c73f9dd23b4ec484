"""The averaged model's per-fin forcing cache: scaled averaged forcing and yaw-oscillation phasor.

The averaged model (eq. 25) holds each fin's averaged force constant over a
half-stroke. Evaluating it (the K polynomial and splines, the Bessel average)
costs more than a whole RK4 step, so it is computed when a fin latches a
pattern and kept, with the pattern it belongs to, until the pattern changes:

* ``cache`` ``(n, 2, CACHE_FIELDS)``, one row per fish and fin (0 right, 1 left):

=================  =====  ======  ==================================================================
field              index  unit    meaning
=================  =====  ======  ==================================================================
``KEY_BIAS``       0      rad     pattern the row was computed for: bias ``gamma_0``
``KEY_AMPLITUDE``  1      rad     amplitude ``gamma_A``
``KEY_PERIOD``     2      s       period ``T_p``
``KEY_RATIO``      3      -       ratio ``zeta``
``AVG_FX``         4      N       ``K_fx f_hx_avg`` (eq. 25)
``AVG_FY``         5      N       ``K_fy f_hy_avg`` (or ``K_fy base``), signed by side
``AVG_TAU``        6      N m     ``K_m tau_avg``, signed by side
``OSC_COS``        7      rad/s   phasor ``A cos(phi)`` of the yaw-rate oscillation, signed by side
``OSC_SIN``        8      rad/s   ``A sin(phi)``
``CACHED``         9      -       1.0 when the row is valid for the key (0: recompute at the next latch)
``PREV_BIAS``      10     rad     pattern of the fin's last finished power stroke (``transitions``,
``PREV_AMPLITUDE`` 11     rad     ``docs/model.md`` section 3.7): bias, amplitude, period, ratio;
``PREV_PERIOD``    12     s       zero after :func:`clear`
``PREV_RATIO``     13     -
=================  =====  ======  ==================================================================

The row depends on the fish's coefficients too: :func:`invalidate` after
changing them. :func:`clear` zeroes rows (no forcing until the next latch), as
at a reset: a fin that stays at rest never latches.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from pectoral_gym._jit import JIT
from pectoral_gym.averaging import averaged_fin_forcing
from pectoral_gym.ktables import yaw_oscillation_phasor
from pectoral_gym.strokes import ANGLE_FROM, ANGLE_TO, ELAPSED, PERIOD, POWER, RATIO, SIDE

__all__ = [
    "CACHE_FIELDS", "KEY_BIAS", "KEY_AMPLITUDE", "KEY_PERIOD", "KEY_RATIO",
    "AVG_FX", "AVG_FY", "AVG_TAU", "OSC_COS", "OSC_SIN", "CACHED",
    "PREV_BIAS", "PREV_AMPLITUDE", "PREV_PERIOD", "PREV_RATIO",
    "clear", "invalidate", "refresh", "yaw_oscillation",
]

KEY_BIAS, KEY_AMPLITUDE, KEY_PERIOD, KEY_RATIO = 0, 1, 2, 3
AVG_FX, AVG_FY, AVG_TAU = 4, 5, 6
OSC_COS, OSC_SIN = 7, 8
CACHED = 9
PREV_BIAS, PREV_AMPLITUDE, PREV_PERIOD, PREV_RATIO = 10, 11, 12, 13
CACHE_FIELDS = 14


def invalidate(cache: np.ndarray, index: np.ndarray | slice | None = None) -> None:
    """Mark the rows of the fish in ``index`` (all if ``None``) stale, e.g. after their coefficients changed."""
    cache[slice(None) if index is None else index, :, CACHED] = 0.0


def clear(cache: np.ndarray, index: np.ndarray | slice | None = None) -> None:
    """Zero the rows of the fish in ``index`` (all if ``None``): no forcing until their fins latch."""
    cache[slice(None) if index is None else index] = 0.0


@nb.njit(inline="always", **JIT)
def refresh(cache, i, f, bias, amplitude, period, ratio, coef, mode, tables):
    """Make fin ``f`` of fish ``i``'s row hold the forcing of pattern ``(bias, amplitude, period, ratio)``.

    Nothing is computed when the row already holds it (the same pattern as the last half-stroke).
    """
    if (cache[i, f, CACHED] == 1.0 and cache[i, f, KEY_BIAS] == bias and cache[i, f, KEY_AMPLITUDE] == amplitude
            and cache[i, f, KEY_PERIOD] == period and cache[i, f, KEY_RATIO] == ratio):
        return
    cache[i, f, KEY_BIAS] = bias
    cache[i, f, KEY_AMPLITUDE] = amplitude
    cache[i, f, KEY_PERIOD] = period
    cache[i, f, KEY_RATIO] = ratio
    fx, fy, tau = averaged_fin_forcing(bias, amplitude, period, ratio, SIDE[f], coef[i], mode, tables)
    cache[i, f, AVG_FX] = fx
    cache[i, f, AVG_FY] = fy
    cache[i, f, AVG_TAU] = tau
    pc, ps = yaw_oscillation_phasor(bias, amplitude, period, ratio, tables)
    cache[i, f, OSC_COS] = SIDE[f] * pc  # the left fin's yaw oscillation is the mirror image
    cache[i, f, OSC_SIN] = SIDE[f] * ps
    cache[i, f, CACHED] = 1.0


@nb.njit(inline="always", **JIT)
def yaw_oscillation(fins, cache, i, offset, idle0, idle1):
    """Amplitude [rad/s] of the yaw-rate oscillation both fins drive, ``offset`` s into the segment.

    Each fin's oscillation is ``Re(P e^{i theta})`` with its phasor ``P`` and
    its beat phase ``theta = 2 pi t / T_p`` (``t`` from the start of its power
    stroke, read from the fin state of :mod:`pectoral_gym.strokes`); the two add
    as phasors. Fins beating in phase with the same pattern cancel (straight
    swimming has no yaw oscillation); fins with different periods drift
    through all relative phases.
    """
    re = 0.0
    im = 0.0
    for f in range(2):
        if (idle0 if f == 0 else idle1) or fins[i, f, ANGLE_FROM] == fins[i, f, ANGLE_TO]:
            continue
        if cache[i, f, OSC_COS] == 0.0 and cache[i, f, OSC_SIN] == 0.0:
            continue  # no yaw-oscillation data (or no stroke): skip the trigonometry
        period = fins[i, f, PERIOD]
        t = fins[i, f, ELAPSED] + offset
        if fins[i, f, POWER] < 0.5:
            t += period / (fins[i, f, RATIO] + 1.0)  # recovery follows the power stroke
        theta = 2.0 * math.pi * t / period
        c, s = math.cos(theta), math.sin(theta)
        re += cache[i, f, OSC_COS] * c - cache[i, f, OSC_SIN] * s
        im += cache[i, f, OSC_COS] * s + cache[i, f, OSC_SIN] * c
    return math.sqrt(re * re + im * im)
