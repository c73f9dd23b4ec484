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
file carries the fin's yaw oscillation (:mod:`pectoral_gym.kfunctions`);
``A`` is then the sinusoid amplitude with the oscillation's mean absolute
value, so the slope at ``w = 0`` is exact, and two fins combine as phasors.

Everything here is compiled with numba and works on scalars, so the
integrators can re-evaluate the forcing when a fin latches new parameters.
"""

from __future__ import annotations

import math

import numba as nb

from pectoral_gym.dynamics import body_accel
from pectoral_gym.kfunctions import ScalingFunctions, oscillation_phasor, spline_values
from pectoral_gym.params import FinBeat, FishParams, coefficient_vector

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
]

EXACT = 0
TAYLOR = 1
_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}


@nb.njit(**_JIT)
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


@nb.njit(**_JIT)
def _k_value(which: int, bias: float, amplitude: float, period: float, ratio: float, k_powers, k_coefs) -> float:
    """Evaluate the polynomial part of scaling function ``which`` (0 K_fx, 1 K_fy, 2 K_m) as a sum of monomials.

    Features, in order: bias [rad], amplitude [rad], period [s], ratio [-], 1/period [1/s], 1/ratio [-].
    """
    total = 0.0
    for j in range(k_coefs.shape[1]):
        c = k_coefs[which, j]
        if c == 0.0:
            continue
        p = k_powers[which, j]
        # integer exponents (the file format allows no others): multiplications instead of pow()
        total += (
            c * _ipow(bias, p[0]) * _ipow(amplitude, p[1]) * _ipow(period, p[2]) * _ipow(ratio, p[3])
            * _ipow(1.0 / period, p[4]) * _ipow(1.0 / ratio, p[5])
        )
    return total


@nb.njit(**_JIT)
def _ipow(x: float, exponent: float) -> float:
    """``x ** exponent`` for a small non-negative integer ``exponent``, by repeated multiplication."""
    result = 1.0
    for _ in range(int(exponent)):
        result *= x
    return result


@nb.njit(**_JIT)
def scaling_values(bias: float, amplitude: float, period: float, ratio: float, kfun):
    """``(K_fx, K_fy, K_m)`` at one pattern: polynomial part plus spline part.

    ``kfun`` is :meth:`pectoral_gym.kfunctions.ScalingFunctions.kernel_arrays`.
    """
    k_powers, k_coefs, knots, table = kfun[0], kfun[1], kfun[2], kfun[3]
    sx, sy, sm = spline_values(bias, amplitude, 1.0 / ratio, knots, table)
    return (
        _k_value(0, bias, amplitude, period, ratio, k_powers, k_coefs) + sx,
        _k_value(1, bias, amplitude, period, ratio, k_powers, k_coefs) + sy,
        _k_value(2, bias, amplitude, period, ratio, k_powers, k_coefs) + sm,
    )


@nb.njit(**_JIT)
def averaged_fin_forcing(
    bias: float,
    amplitude: float,
    period: float,
    ratio: float,
    side: float,
    coef,
    mode: int,
    kfun,
):
    """Scaled cycle-averaged force and moment of one fin on the body (eq. 25).

    Args:
        bias, amplitude, period, ratio: The fin's beat pattern (rad, rad, s, -).
        side: +1 for the right fin, -1 for the left (mirror image).
        coef: Packed coefficients (``params.COEF_NAMES``).
        mode: :data:`EXACT` or :data:`TAYLOR`.
        kfun: Scaling functions, :meth:`pectoral_gym.kfunctions.ScalingFunctions.kernel_arrays`.

    Returns:
        ``(K_fx f_hx_avg, K_fy f_hy_avg, K_m tau_avg)`` in N, N, N m; with
        ``sway = "base"`` the sway term is ``K_fy base`` (``kfunctions``).
    """
    drag_constant = coef[6]
    fin_offset = coef[8]
    c = drag_constant * math.pi**2 * (ratio * ratio - 1.0) / (ratio * period * period)
    a2 = amplitude * amplitude
    if mode == EXACT:
        base = c * amplitude * bessel_j1(amplitude)
        fx = base * math.sin(bias)
        fy = base * math.cos(bias)
    else:
        b2 = bias * bias
        base = c * a2 * (8.0 - a2) / 16.0  # second-order Taylor form of the exact base (as in eq. 27)
        fx = c * bias * a2 * (24.0 - 3.0 * a2 - 4.0 * b2) / 48.0  # eq. (26)
        fy = c * a2 * (8.0 - a2 - 4.0 * b2) / 16.0  # eq. (27)
    tau = fin_offset * fx  # eq. (18)/(28): right fin pivot at y = -C_p
    kx, ky, km = scaling_values(bias, amplitude, period, ratio, kfun)
    sway = ky * base if kfun[4] == 1.0 else ky * fy
    return kx * fx, side * sway, side * km * tau


@nb.njit(**_JIT)
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


@nb.njit(**_JIT)
def oscillating_square_mean(mean: float, amplitude: float) -> float:
    """Cycle mean of ``x|x|`` for ``x = mean + amplitude sin(theta)``, ``theta`` uniform over a cycle.

    With ``u = mean / amplitude`` and ``a = arcsin(u)`` the mean is
    ``amplitude^2 ((2 a / pi)(u^2 + 1/2) + (3 / pi) u sqrt(1 - u^2))`` for ``|u| < 1``
    (``x`` changes sign within the cycle) and ``sign(u) amplitude^2 (u^2 + 1/2)``
    otherwise; it is odd in ``mean``, continuously differentiable, has slope
    ``4 amplitude / pi`` at ``mean = 0`` and is ``mean |mean|`` for zero amplitude.
    """
    if amplitude <= 0.0:
        return mean * abs(mean)
    u = mean / amplitude
    a2 = amplitude * amplitude
    if abs(u) >= 1.0:
        return math.copysign(a2 * (u * u + 0.5), u)
    return a2 * (2.0 * math.asin(u) / math.pi * (u * u + 0.5) + 3.0 / math.pi * u * math.sqrt(1.0 - u * u))


@nb.njit(**_JIT)
def averaged_body_accel(vx, vy, omega, fx, fy, tau, m1, m2, j3, c1, c2, c4, oscillation):
    """Eqs. (19)-(20) of the averaged model, with the oscillation-averaged yaw damping.

    :func:`pectoral_gym.dynamics.body_accel` with ``c4 omega|omega|`` replaced by its mean over an
    in-beat yaw oscillation of amplitude ``oscillation`` [rad/s],
    ``c4 oscillating_square_mean(omega, oscillation)`` (unchanged for 0).
    """
    dvx, dvy, dom = body_accel(vx, vy, omega, fx, fy, tau, m1, m2, j3, c1, c2, c4)
    if oscillation > 0.0:
        dom += c4 * (omega * abs(omega) - oscillating_square_mean(omega, oscillation))
    return dvx, dvy, dom


@nb.njit(**_JIT)
def yaw_oscillation_phasor(bias: float, amplitude: float, period: float, ratio: float, kfun):
    """Phasor ``A (cos phi, sin phi)`` [rad/s] of the yaw-rate oscillation one right fin drives.

    ``A T_p`` and ``phi`` come from the scaling file (:func:`pectoral_gym.kfunctions.oscillation_phasor`);
    ``(0, 0)`` without yaw-oscillation data.
    """
    pc, ps = oscillation_phasor(bias, amplitude, 1.0 / ratio, kfun[5], kfun[6])
    return pc / period, ps / period


_UNIT_K = ScalingFunctions.unit()


def averaged_forcing(
    beat: FinBeat,
    params: FishParams | None = None,
    side: str = "right",
    mode: int = EXACT,
    scaling=None,
) -> tuple[float, float, float]:
    """Convenience wrapper: scaled averaged ``(f_hx, f_hy, tau)`` of one fin.

    Args:
        beat: The fin's pattern.
        params: Model parameters (Table 1 defaults if ``None``).
        side: ``"right"`` or ``"left"``.
        mode: :data:`EXACT` (default) or :data:`TAYLOR`.
        scaling: A :class:`~pectoral_gym.kfunctions.ScalingFunctions`, or ``None`` for K = 1.
    """
    if side not in ("right", "left"):
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")
    params = params or FishParams()
    scaling = _UNIT_K if scaling is None else scaling
    return averaged_fin_forcing(
        beat.bias, beat.amplitude, beat.period, beat.ratio,
        1.0 if side == "right" else -1.0,
        coefficient_vector(params), mode, scaling.kernel_arrays(),
    )
