"""Cycle-averaged fin forcing (eqs. 25-28) and the scaling functions K.

The averaged model (eq. 25) replaces each fin's periodic force by its average
over one fin-beat cycle, scaled by ``K_fx, K_fy, K_m``. Two forms are offered:

* ``EXACT`` (default): the closed-form average (``docs/model.md``)::

      f_hx_avg = k pi^2 (zeta^2 - 1) / (zeta T_p^2) * gA J1(gA) * sin(g0)
      f_hy_avg = k pi^2 (zeta^2 - 1) / (zeta T_p^2) * gA J1(gA) * cos(g0)

  with ``k = lambda rho D_p S_p^3 / 6``. The fin's inertial terms average to
  exactly zero (they are time derivatives of periodic functions).
* ``TAYLOR``: the paper's second-order Taylor forms (26)-(28), with ``l_p = 1``
  and ``S_p^3`` in (27) and (28) where the extraction lost it, and without the
  ``m_p`` terms of (27) (dimensionally inconsistent, and zero in the exact
  average). See ``docs/model.md``, errata.

**Oscillation-averaged yaw damping** (beyond the paper). Within a beat the
yaw rate oscillates, ``omega = w + omega~(t)``, by more than its mean ``w``
when the fish turns slowly. The cycle average of the yaw damping
``c4 omega|omega|`` of eq. (20) is then not ``c4 w|w|``: for a sinusoidal
``omega~ = A sin(theta)`` it is ``c4 A^2 q(w / A)`` (:func:`oscillating_square_mean`),
linear in ``w`` near zero (slope ``4 c4 A / pi``). Without that damping the
Munk moment ``(m1 - m2) vx vy`` of eq. (20) holds a spurious turn in the
opposite direction for some patterns, which no scaling function can remove
(``docs/model.md``, section 3.6). The averaged model uses it when the scaling
file carries the fin's yaw oscillation (:mod:`pectoral_gym.model.kfunctions`);
``A`` is then the sinusoid amplitude with the oscillation's mean absolute
value, so the slope at ``w = 0`` is exact, and two fins combine as phasors.

Everything here is compiled with numba and works on scalars, so the model
kernels can re-evaluate the forcing when a fin latches new parameters
(:mod:`pectoral_gym.model.forcing_cache`). The yaw damping itself is
:func:`pectoral_gym.model.dynamics.body_accel` with its ``oscillation`` argument; the
K evaluation is :mod:`pectoral_gym.model.ktables`.
"""

from __future__ import annotations

import math

import numpy as np

from pectoral_gym.model.dynamics import body_accel, oscillating_square_mean
from pectoral_gym.model.fast_step import short_bessel_j1, sin_cos_of_angle
from pectoral_gym.model.jit import njit
from pectoral_gym.model.kfunctions import UNIT_K
from pectoral_gym.model.ktables import KTables, scaling_values, yaw_oscillation_phasor
from pectoral_gym.model.params import FIN_FORCE_SCALE, Coef, FinBeat, FishParams, coefficient_vector

__all__ = [
    "EXACT",
    "TAYLOR",
    "bessel_j1",
    "averaged_fin_forcing",
    "averaged_body_accel",
    "mean_fin_power",
    "oscillating_square_mean",
    "yaw_oscillation_phasor",
    "averaged_forcing",
    "scaling_values",
    "scaled_forcing",
    "half_stroke_mean_force",
    "power_stroke_excess",
    "ODD_MOMENT_SERIES",
    "odd_moment",
    "short_odd_moment",
    "ripple_offset",
]

EXACT = 0
TAYLOR = 1


def averaged_body_accel(vx, vy, omega, fx, fy, tau, m1, m2, j3, c1, c2, c4, oscillation=0.0):
    """Eqs. (19)-(20) with the averaged model's yaw damping (``docs/model.md`` 3.6), for Python callers.

    ``oscillation``: the sinusoid amplitude [rad/s] (0: eq. 20); :func:`pectoral_gym.model.dynamics.body_accel`.
    """
    return body_accel(vx, vy, omega, fx, fy, tau, m1, m2, j3, c1, c2, c4, float(oscillation))


@njit
def bessel_j1(x: float) -> float:
    """Bessel function ``J1(x)`` by its power series, for ``|x| <= pi``.

    Fin amplitudes never exceed pi/2 (the stroke must stay in [0, pi]), where
    18 terms reach machine precision.
    """
    half = 0.5 * x
    term = half
    total = half
    h2 = half * half
    for k in range(1, 18):
        term *= -h2 / (k * (k + 1))
        total += term
    return total


@njit(inline="always")
def _j1(x: float, fast: bool) -> float:
    """:func:`bessel_j1`, or with ``fast`` (the averaged model's fast step) its nine-term form within ``pi/2``."""
    if fast and abs(x) <= 0.5 * math.pi:
        return short_bessel_j1(x)
    return bessel_j1(x)


@njit(inline="always")
def _sin_cos(angle: float, fast: bool):
    """``sin, cos`` of a fin angle: libm's, or with ``fast`` :func:`~pectoral_gym.model.fast_step.sin_cos_of_angle`."""
    if fast:
        return sin_cos_of_angle(angle)
    return math.sin(angle), math.cos(angle)


@njit
def half_stroke_mean_force(angle_from: float, angle_to: float, duration: float, drag_constant: float,
                           fast: bool = False):
    """Exact mean blade-element force of one half-cosine half-stroke of the right fin (``docs/model.md`` 3.7).

    The half-stroke ``g = mid - half cos(pi s / d)`` (:func:`pectoral_gym.model.dynamics.stroke_kinematics`)
    from ``angle_from`` to ``angle_to`` in ``duration`` s. The inertial terms of
    eqs. (16)-(17) are the time derivatives of ``m_p S_p/2 g' sin g`` and
    ``m_p S_p/2 g' cos g`` and average to zero (``g' = 0`` at both ends); the drag term gives::

        mean f_hx = k pi^2 |half| J1(half) sin(mid) / d^2,   mean f_hy = (same) cos(mid)

    ``fast``: the averaged model's fast step's ``J1``, ``sin`` and ``cos`` (:mod:`pectoral_gym.model.fast_step`).

    Returns:
        ``(f_hx, f_hy)`` [N]; the moment is ``C_p f_hx`` (eq. 18).
    """
    half = 0.5 * (angle_to - angle_from)
    mid = 0.5 * (angle_to + angle_from)
    base = drag_constant * math.pi * math.pi * abs(half) * _j1(half, fast) / (duration * duration)
    sin_mid, cos_mid = _sin_cos(mid, fast)
    return base * sin_mid, base * cos_mid


def _odd_moment_coefficients(terms: int = 14) -> tuple[float, ...]:
    """``q_n = int_0^pi (phi - pi/2) sin^2(phi) cos^(2n+1)(phi) dphi`` (Gauss-Legendre, exact to rounding).

    The integrands are polynomials in ``cos`` and ``sin`` times ``phi``; 64 nodes integrate
    them to machine precision (``q_0 = -4/9``).
    """
    x, w = np.polynomial.legendre.leggauss(64)
    phi, w = (x + 1.0) * math.pi / 2.0, w * math.pi / 2.0
    return tuple(float(np.sum(w * (phi - math.pi / 2.0) * np.sin(phi) ** 2 * np.cos(phi) ** (2 * n + 1)))
                 for n in range(terms))


#: Series coefficients of :func:`odd_moment` (14 terms reach rounding for ``|h| <= pi/2``); also symbolic_corrections'.
ODD_MOMENT_SERIES = _odd_moment_coefficients()


@njit
def odd_moment(h: float) -> float:
    """``Q(h) = int_0^pi (phi - pi/2) sin^2(phi) sin(h cos phi) dphi``, by its power series (``|h| <= pi/2``).

    ``sin(h cos phi) = sum_n (-1)^n (h cos phi)^(2n+1) / (2n+1)!``, integrated term by term
    (:func:`_odd_moment_coefficients`). Odd in ``h``, ``Q(h) ~ -4h/9`` for small ``h``.
    """
    h2 = h * h
    term = h  # (-1)^n h^(2n+1) / (2n+1)!
    total = 0.0
    for n in range(len(ODD_MOMENT_SERIES)):
        total += ODD_MOMENT_SERIES[n] * term
        term *= -h2 / ((2 * n + 2) * (2 * n + 3))
    return total


#: ``ODD_MOMENT_SERIES[n] (-1)^n / (2n+1)!``: :func:`odd_moment`'s coefficients of ``h^(2n+1)``, for its short form.
_ODD_MOMENT_POWERS = tuple(q * (-1.0) ** n / math.factorial(2 * n + 1) for n, q in enumerate(ODD_MOMENT_SERIES))
#: Terms of :func:`short_odd_moment`: for ``|h| <= pi/2`` the first left out is below
#: ``(pi^2/4) |h|^19 / 19! = 1.1e-13`` (``|q_n| <= int_0^pi |phi - pi/2| dphi = pi^2/4``), the rest far less.
SHORT_ODD_MOMENT_TERMS = 9


@njit
def short_odd_moment(h: float) -> float:
    """:func:`odd_moment` for ``|h| <= pi/2`` by its first nine terms, coefficients precomputed (Horner's form)."""
    s = h * h
    total = _ODD_MOMENT_POWERS[SHORT_ODD_MOMENT_TERMS - 1]
    for n in range(SHORT_ODD_MOMENT_TERMS - 2, -1, -1):
        total = total * s + _ODD_MOMENT_POWERS[n]
    return h * total


@njit
def ripple_offset(bias: float, amplitude: float, period: float, ratio: float, drag_constant: float,
                  fast: bool = False):
    """Beat-mean impulse offset [N s] of the right fin's regular beat over its cycle average (``docs/model.md`` 3.8).

    ``M = (1/T) int_0^T E(t) dt`` with ``E(t) = int_0^t (f - fbar) ds`` the blade-element
    force's impulse beyond the cycle average since the start of a power stroke: a fish whose
    fin starts a power stroke at velocity ``v`` has a beat-mean velocity ``v + M / m`` (without
    damping). In closed form (the inertial terms of eqs. 16-17 contribute nothing)::

        M_x = k pi^2 gA J1(gA) sin(g0) (zeta + 1/zeta) / (2 T) + 2 k gA^2 cos(g0) Q(gA) / T
        M_y = k pi^2 gA J1(gA) cos(g0) (zeta + 1/zeta) / (2 T) - 2 k gA^2 sin(g0) Q(gA) / T

    with :func:`odd_moment` ``Q``. Zero for a fin at rest. ``fast``: the fast step's ``J1``, ``Q``, ``sin``, ``cos``.

    Returns:
        ``(M_x, M_y)``; the moment's is ``C_p M_x`` (eq. 18).
    """
    if amplitude == 0.0:
        return 0.0, 0.0
    a = drag_constant * math.pi * math.pi * amplitude * _j1(amplitude, fast) * (ratio + 1.0 / ratio) / (2.0 * period)
    q = short_odd_moment(amplitude) if fast and amplitude <= 0.5 * math.pi else odd_moment(amplitude)
    b = 2.0 * drag_constant * amplitude * amplitude * q / period
    sin_bias, cos_bias = _sin_cos(bias, fast)
    return a * sin_bias + b * cos_bias, a * cos_bias - b * sin_bias


@njit
def power_stroke_excess(bias: float, amplitude: float, period: float, ratio: float, drag_constant: float,
                        fast: bool = False):
    """Impulse [N s] a regular power stroke delivers beyond the cycle mean over its duration (right fin, K = 1).

    ``X = d1 (mean_power - mean_cycle)`` with ``d1 = T_p / (zeta + 1)`` (eq. 21); the recovery stroke
    delivers ``-X``, so ``X`` is the running impulse offset between the blade-element and the averaged
    forcing after a power stroke (``docs/model.md`` section 3.7).

    Returns:
        ``(X_fx, X_fy)``; the moment's is ``C_p X_fx`` (eq. 18).
    """
    if amplitude == 0.0:
        return 0.0, 0.0
    d1 = period / (ratio + 1.0)
    d2 = ratio * d1
    px, py = half_stroke_mean_force(bias - amplitude, bias + amplitude, d1, drag_constant, fast)
    rx, ry = half_stroke_mean_force(bias + amplitude, bias - amplitude, d2, drag_constant, fast)
    return d1 * px - d1 * (d1 * px + d2 * rx) / period, d1 * py - d1 * (d1 * py + d2 * ry) / period


@njit
def averaged_fin_forcing(
    bias: float,
    amplitude: float,
    period: float,
    ratio: float,
    side: float,
    coef,
    mode: int,
    tables: KTables,
):
    """Scaled cycle-averaged force and moment of one fin on the body (eq. 25).

    Args:
        bias, amplitude, period, ratio: The pattern the fin actually beats (rad, rad, s, -): for a fin with a
            servo map, the commanded pattern mapped by it (:meth:`FishParams.fin_actual_beat`).
        side: +1 for the right fin, -1 for the left (mirror image); it picks the fin's force factor too.
        coef: Packed coefficients of one fish (``params.COEF_NAMES``).
        mode: :data:`EXACT` or :data:`TAYLOR`.
        tables: Scaling functions, :meth:`pectoral_gym.model.kfunctions.ScalingFunctions.kernel_arrays`.

    Returns:
        ``(K_fx f_hx_avg, K_fy f_hy_avg, K_m tau_avg)`` in N, N, N m; with
        ``sway = "base"`` the sway term is ``K_fy base`` (``kfunctions``). Linear in the fin's ``k``.
    """
    kx, ky, km = scaling_values(bias, amplitude, period, ratio, tables)
    return scaled_forcing(bias, amplitude, period, ratio, side, coef, mode, kx, ky, km, tables.base_sway)


@njit
def scaled_forcing(bias, amplitude, period, ratio, side, coef, mode, kx, ky, km, base_sway, fast=False):
    """:func:`averaged_fin_forcing` with the scaling values ``K_fx, K_fy, K_m`` given (eq. 25).

    ``base_sway``: :attr:`pectoral_gym.model.ktables.KTables.base_sway`. The averaged model's latch
    evaluates K together with the yaw-oscillation phasor (:func:`pectoral_gym.model.ktables.pattern_values`).
    ``fast``: the fast step's ``J1``, ``sin`` and ``cos`` (:mod:`pectoral_gym.model.fast_step`).
    """
    drag_constant = coef[Coef.FIN_DRAG_CONSTANT] * coef[FIN_FORCE_SCALE[0 if side > 0.0 else 1]]  # the fin's k
    fin_offset = coef[Coef.FIN_OFFSET]
    c = drag_constant * math.pi**2 * (ratio * ratio - 1.0) / (ratio * period * period)
    a2 = amplitude * amplitude
    if mode == EXACT:
        base = c * amplitude * _j1(amplitude, fast)
        sin_bias, cos_bias = _sin_cos(bias, fast)
        fx = base * sin_bias
        fy = base * cos_bias
    else:
        b2 = bias * bias
        base = c * a2 * (8.0 - a2) / 16.0  # second-order Taylor form of the exact base (as in eq. 27)
        fx = c * bias * a2 * (24.0 - 3.0 * a2 - 4.0 * b2) / 48.0  # eq. (26)
        fy = c * a2 * (8.0 - a2 - 4.0 * b2) / 16.0  # eq. (27)
    tau = fin_offset * fx  # eq. (18)/(28): right fin pivot at y = -C_p
    sway = ky * base if base_sway else ky * fy
    return kx * fx, side * sway, side * km * tau


@njit
def mean_fin_power(amplitude: float, period: float, ratio: float, span: float, drag_constant: float) -> float:
    """Mean hydrodynamic power one fin delivers to the water [W].

    The fin moment about its pivot (eq. 14) is ``M = -(lambda rho D_p S_p^4 / 8) g'|g'|``,
    so the power is ``(3 k S_p / 4) |g'|^3``; over a cycle of eq. (21) its mean
    is ``(3 k S_p / 4) (4/3) gA^3 (w1^2 + w2^2) / T_p`` with the two stroke
    rates ``w1 = pi (zeta + 1) / T_p`` and ``w2 = w1 / zeta``. The fin's
    inertial work averages to zero.
    """
    w1 = math.pi * (ratio + 1.0) / period
    w2 = w1 / ratio
    return drag_constant * span * amplitude**3 * (w1 * w1 + w2 * w2) / period


def averaged_forcing(
    beat: FinBeat,
    params: FishParams | None = None,
    side: str = "right",
    mode: int = EXACT,
    scaling=None,
) -> tuple[float, float, float]:
    """Convenience wrapper: scaled averaged ``(f_hx, f_hy, tau)`` of one fin.

    Args:
        beat: The fin's commanded pattern (mapped by the fin's servo map of ``params``).
        params: Model parameters (Table 1 defaults if ``None``).
        side: ``"right"`` or ``"left"``.
        mode: :data:`EXACT` (default) or :data:`TAYLOR`.
        scaling: A :class:`~pectoral_gym.model.kfunctions.ScalingFunctions`, or ``None`` for K = 1.
    """
    if side not in ("right", "left"):
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")
    params = params or FishParams()
    scaling = UNIT_K if scaling is None else scaling
    beat = params.fin_actual_beat(beat, side)
    return averaged_fin_forcing(
        beat.bias, beat.amplitude, beat.period, beat.ratio,
        1.0 if side == "right" else -1.0,
        coefficient_vector(params), mode, scaling.kernel_arrays(),
    )
