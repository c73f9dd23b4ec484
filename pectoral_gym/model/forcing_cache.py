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
``WAVE``           14-29  rad/s   ``Re, Im`` of the yaw-waveform harmonics ``c_1 .. c_8`` (``docs/model.md``
                                  3.6), signed by side; zero beyond the file's harmonics
``REF_ABS``        30     rad/s   mean ``|omega|`` of the pattern's reference run (0: none)
``TR_FX``          31     N       the half-stroke in progress's transitional forcing (``transitions``,
``TR_FY``          32     N       ``docs/model.md`` section 3.7; ``stroke_corrections._transition``),
``TR_TAU``         33     N m     signed by side; set when the fin latches, zero after :func:`clear`
``OFF_FX``         34     N s     the beat-mean ripple offset delivered so far (``ripple_offsets``,
``OFF_FY``         35     N s     ``docs/model.md`` 3.8: ``M`` of the fin's latched pattern,
``OFF_TAU``        36     N m s   :func:`pectoral_gym.model.averaging.ripple_offset`), signed by side; zero
                                  after :func:`clear`
``OSC_EXCESS``     37     -       the half-stroke in progress's yaw-oscillation gain minus one
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

from pectoral_gym.model.averaging import add_harmonic, scaled_forcing
from pectoral_gym.model.jit import njit
from pectoral_gym.model.ktables import (
    MAX_HARMONICS,
    MAX_SAMPLES,
    QUADRATURE,
    RATE_ITERATIONS,
    pattern_values,
    quadrature_window,
    waveform_harmonics_into,
)
from pectoral_gym.model.strokes import ANGLE_FROM, ANGLE_TO, ELAPSED, PERIOD, POWER, RATIO, SIDE

__all__ = [
    "CACHE_FIELDS", "KEY_BIAS", "KEY_AMPLITUDE", "KEY_PERIOD", "KEY_RATIO",
    "AVG_FX", "AVG_FY", "AVG_TAU", "OSC_COS", "OSC_SIN", "CACHED",
    "PREV_BIAS", "PREV_AMPLITUDE", "PREV_PERIOD", "PREV_RATIO", "WAVE", "REF_ABS", "TR_FX", "TR_FY", "TR_TAU",
    "OFF_FX", "OFF_FY", "OFF_TAU", "OSC_EXCESS",
    "QUADRATURE", "WORKSPACE",
    "RATE_ITERATIONS",
    "clear", "invalidate", "refresh", "window_samples", "yaw_oscillation", "yaw_waveform",
]

KEY_BIAS, KEY_AMPLITUDE, KEY_PERIOD, KEY_RATIO = 0, 1, 2, 3
AVG_FX, AVG_FY, AVG_TAU = 4, 5, 6
OSC_COS, OSC_SIN = 7, 8
CACHED = 9
PREV_BIAS, PREV_AMPLITUDE, PREV_PERIOD, PREV_RATIO = 10, 11, 12, 13
WAVE = 14
REF_ABS = WAVE + 2 * MAX_HARMONICS
TR_FX, TR_FY, TR_TAU = REF_ABS + 1, REF_ABS + 2, REF_ABS + 3
OFF_FX, OFF_FY, OFF_TAU = TR_TAU + 1, TR_TAU + 2, TR_TAU + 3
OSC_EXCESS = OFF_TAU + 1
CACHE_FIELDS = OSC_EXCESS + 1

_FIN = MAX_SAMPLES  # per fin: Re, Im of its harmonics at the segment's phase, then its drive
WORKSPACE = _FIN + 8 * MAX_HARMONICS


def invalidate(cache: np.ndarray, index: np.ndarray | slice | None = None) -> None:
    """Mark the rows of the fish in ``index`` (all if ``None``) stale, e.g. after their coefficients changed."""
    cache[slice(None) if index is None else index, :, CACHED] = 0.0


def clear(cache: np.ndarray, index: np.ndarray | slice | None = None) -> None:
    """Zero the rows of the fish in ``index`` (all if ``None``): no forcing until their fins latch."""
    cache[slice(None) if index is None else index] = 0.0


@njit(inline="always")
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
    kx, ky, km, pc, ps = pattern_values(bias, amplitude, period, ratio, tables)
    fx, fy, tau = scaled_forcing(bias, amplitude, period, ratio, SIDE[f], coef[i], mode, kx, ky, km, tables.base_sway)
    cache[i, f, AVG_FX] = fx
    cache[i, f, AVG_FY] = fy
    cache[i, f, AVG_TAU] = tau
    cache[i, f, OSC_COS] = SIDE[f] * pc  # the left fin's yaw oscillation is the mirror image
    cache[i, f, OSC_SIN] = SIDE[f] * ps
    if tables.wave_table.shape[1] > 0:  # read only with a yaw_waveform section (stepping.advance_one)
        waveform_harmonics_into(bias, amplitude, period, ratio, tables, SIDE[f], cache[i, f], WAVE)
    cache[i, f, CACHED] = 1.0


@njit(inline="always")
def yaw_oscillation(fins, cache, i, offset, idle0, idle1):
    """Amplitude [rad/s] of the yaw-rate oscillation both fins drive, ``offset`` s into the segment.

    Each fin's oscillation is ``Re(G P e^{i theta})`` with its phasor ``P``, the gain ``G`` of
    its half-stroke in progress (``OSC_EXCESS``, 1 on regular half-strokes) and its beat phase
    ``theta = 2 pi t / T_p`` (``t`` from the start of its power stroke, read from the fin state
    of :mod:`pectoral_gym.model.strokes`); the two add
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
        theta = _beat_phase(fins, i, f, offset)
        gain = 1.0 + cache[i, f, OSC_EXCESS]  # a transitional half-stroke's (docs/model.md 3.9)
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


@njit
def window_samples(work, harmonics, n, cycles0, cycles1):
    """The samples ``work[:n]`` of both fins' waveforms over a window; returns ``(pi/2) mean|.|``.

    Fin ``f``'s harmonics ``R_{f,k}`` (``work[_FIN + 4 MAX_HARMONICS f + 2 k]``, ``+1``) turn by
    ``2 pi k cycles_f / n`` per sample: sample ``j`` is ``Re sum_f sum_k R_{f,k} e^{2 pi i k cycles_f j / n}``
    (a fin that does not beat has zero harmonics). The returned amplitude is that of the
    sinusoid with the same mean absolute value, the stiffness measure of the step rule
    (:func:`pectoral_gym.model.dynamics.linearised_rate`).
    """
    for j in range(n):
        work[j] = 0.0
    for f in range(2):
        cycles = cycles0 if f == 0 else cycles1
        base = _FIN + 4 * MAX_HARMONICS * f
        for k in range(harmonics):
            zr, zi = work[base + 2 * k], work[base + 2 * k + 1]
            if zr == 0.0 and zi == 0.0:
                continue
            add_harmonic(work, n, zr, zi, k + 1, cycles)
    total = 0.0
    for j in range(n):
        total += abs(work[j])
    return 0.5 * math.pi * total / n


@njit
def _mean_abs(work, n, omega):
    total = 0.0
    for j in range(n):
        total += abs(omega + work[j])
    return total / n


@njit
def yaw_waveform(fins, cache, i, offset, idle0, idle1, harmonics, rate, omega, c4, work):
    """Both fins' yaw-rate oscillation over one averaging window, ``offset`` s into the segment.

    Each fin's waveform ``G Re sum_k c_k e^{i k theta}`` (``WAVE`` fields, ``G`` the gain of its
    half-stroke in progress, ``OSC_EXCESS``) starts at its beat phase ``theta_f`` (``docs/model.md``
    3.6). One fin, equal periods, or periods without a common period of at most ``COMMON_BEATS``
    beats of the slower fin: ``QUADRATURE`` samples
    of one beat, both fins keeping their present relative phase (each fin's own waveform is
    covered exactly once). Commensurate periods: the common period, ``QUADRATURE`` samples per
    beat of the faster fin, each fin at its own rate (the exact time average). With ``rate``
    (the file has the reference runs' mean ``|omega|``), harmonic ``k`` of fin ``f`` is the
    response of the linearised yaw damping to the drive ``c_k (lambda_f + i k Omega_f)`` the fin
    exerted in its reference run, ``c_k (lambda_f + i k Omega_f) / (lambda + i k Omega_f)``,
    ``lambda_f = 2 c4 |omega|_ref``, ``lambda = 2 c4 mean|omega + o|`` of the combined waveform
    ``o`` at the yaw rate ``omega`` (``RATE_ITERATIONS`` relaxed fixed-point steps from the
    plain sum). Writes the samples into ``work[:n]`` (a ``WORKSPACE`` array) and returns
    ``(n, equivalent amplitude)`` (:func:`window_samples`).
    """
    for c in range(_FIN, WORKSPACE):
        work[c] = 0.0
    freq0 = freq1 = 0.0
    for f in range(2):
        if (idle0 if f == 0 else idle1) or fins[i, f, ANGLE_FROM] == fins[i, f, ANGLE_TO]:
            continue
        theta = _beat_phase(fins, i, f, offset)
        freq = 2.0 * math.pi / fins[i, f, PERIOD]
        lam = 2.0 * c4 * cache[i, f, REF_ABS]
        if f == 0:
            freq0 = freq
        else:
            freq1 = freq
        base = _FIN + 4 * MAX_HARMONICS * f
        c1, s1 = math.cos(theta), math.sin(theta)
        gain = 1.0 + cache[i, f, OSC_EXCESS]  # a transitional half-stroke's (docs/model.md 3.9)
        c, s = gain * c1, gain * s1
        for k in range(harmonics):  # e^{i k theta} by rotation
            a, b = cache[i, f, WAVE + 2 * k], cache[i, f, WAVE + 2 * k + 1]
            ar, br = a * c - b * s, a * s + b * c
            work[base + 2 * k], work[base + 2 * k + 1] = ar, br
            kw = (k + 1) * freq
            work[base + 2 * MAX_HARMONICS + 2 * k] = ar * lam - br * kw  # drive c_k (lambda_f + i k Omega_f)
            work[base + 2 * MAX_HARMONICS + 2 * k + 1] = br * lam + ar * kw
            c, s = c * c1 - s * s1, s * c1 + c * s1
    n, cycles0, cycles1 = quadrature_window(freq0, freq1)
    amplitude = window_samples(work, harmonics, n, cycles0, cycles1)
    if not rate:
        return n, amplitude
    lam = 2.0 * c4 * _mean_abs(work, n, omega)
    for it in range(RATE_ITERATIONS):
        for f in range(2):
            freq = freq0 if f == 0 else freq1
            if freq == 0.0:
                continue
            base = _FIN + 4 * MAX_HARMONICS * f
            for k in range(harmonics):
                kw = (k + 1) * freq
                dr = work[base + 2 * MAX_HARMONICS + 2 * k]
                di = work[base + 2 * MAX_HARMONICS + 2 * k + 1]
                den = lam * lam + kw * kw
                work[base + 2 * k] = (dr * lam + di * kw) / den  # drive / (lambda + i k Omega_f)
                work[base + 2 * k + 1] = (di * lam - dr * kw) / den
        amplitude = window_samples(work, harmonics, n, cycles0, cycles1)
        if it + 1 < RATE_ITERATIONS:
            lam = 0.5 * (lam + 2.0 * c4 * _mean_abs(work, n, omega))
    return n, amplitude
