"""The averaged model's fast step: bounded-range function approximations and a carried heading (compiled).

The averaged model's ``fast_step`` option (:class:`pectoral_gym.model.models.AveragedModel`) integrates
the same equations (19)-(20) with the oscillation-averaged yaw damping (``docs/model.md`` 3.6) as the
default step, with changes that trade exact libm calls and an explicit step for speed:

* the drift angle ``alpha = arctan(v_y / v_x)`` of eq. (20) by :func:`drift_angle`, an odd polynomial
  on ``[0, 1]`` after the octant reduction (relative error below :data:`ATAN_RELATIVE_ERROR`), instead of
  libm's ``atan2``;
* the ``arcsin`` of :func:`pectoral_gym.model.dynamics.oscillating_square_mean` by :func:`fast_asin`, an
  odd polynomial on ``[0, 1/2]`` and the half-angle identity beyond (relative error below
  :data:`ASIN_RELATIVE_ERROR`), instead of libm's ``asin``;
* the yaw damping's stiffness integrated exactly: each substep is :func:`exponential_substep`,
  exponential time differencing RK4 (Cox and Matthews 2002) in the yaw rate about the damping's
  linearisation, the classical RK4 in the rest, with the heading's ``cos, sin`` carried from substep to
  substep (:func:`rotate`; a segment starts from libm's values of its heading) instead of libm's at every
  substep; the substeps are sized by what the linearisation leaves out (``h * rate <=
  FAST_ACCURATE_STEP``), not by the damping's own rate ``2 c4 |omega|``, so a fish turning steadily
  takes the largest steps (``dt_max``) where the default step takes ``h * 2 c4 |omega| <= 1.5``.

The polynomials' coefficients are least-squares fits of the relative error on Chebyshev nodes
(docs/notes/2026-12-07-fast-averaged-step.md); their error bounds are asserted against libm over their
whole ranges in ``tests/test_fast_step.py``.
"""

from __future__ import annotations

import math

from pectoral_gym.model.dynamics import Forcing, RateConstants, oscillating_square_mean
from pectoral_gym.model.jit import njit
from pectoral_gym.model.params import BodyCoefficients

__all__ = ["ASIN_RELATIVE_ERROR", "ATAN_RELATIVE_ERROR", "BESSEL_J1_ERROR", "FAST_ACCURATE_STEP", "SIN_COS_ERROR",
           "drift_angle", "exponential_substep", "exponential_weights", "fast_asin", "fast_atan_unit",
           "fast_oscillating_square_mean", "rotate",
           "short_bessel_j1", "sin_cos_half_turn", "sin_cos_of_angle"]

#: The fast step's ``h * rate`` bound on the rate :func:`exponential_substep` leaves to its explicit part (the
#: default step's, on the whole rate, is ``stepping.ACCURATE_STEP``, 1.5); RK4 is stable to 2.78.
FAST_ACCURATE_STEP = 2.0
#: Bound of ``|fast_atan_unit(t) / atan(t) - 1|`` on ``[0, 1]`` (measured: 6.8e-11).
ATAN_RELATIVE_ERROR = 1e-10
#: Bound of ``|fast_asin(x) / asin(x) - 1|`` on ``[-1, 1]`` (measured: 9.7e-13 on ``[0, 1/2]``).
ASIN_RELATIVE_ERROR = 2e-12

# atan(t) = t P(t^2) on [0, 1], P of degree 11 in t^2.
_A0, _A1, _A2, _A3 = 0.9999999999318805, -0.33333331350306894, 0.19999903388692686, -0.1428384780907495
_A4, _A5, _A6, _A7 = 0.110921921194746, -0.0897539983718348, 0.07231781144120147, -0.05402101095107094
_A8, _A9, _A10, _A11 = 0.033902265898147224, -0.015884236323876384, 0.0047557486890835755, -0.0006675804427545158
# asin(x) = x Q(x^2) on [0, 1/2], Q of degree 8 in x^2.
_S0, _S1, _S2, _S3 = 1.000000000000859, 0.16666666611539238, 0.07500005803932074, 0.044640516773697944
_S4, _S5, _S6, _S7 = 0.030428878881554426, 0.021849208916507885, 0.02071241431147144, 0.001838661276623078
_S8 = 0.033034918985630234


@njit(inline="always")
def fast_atan_unit(t: float) -> float:
    """``atan(t)`` for ``t`` in ``[0, 1]`` (relative error below :data:`ATAN_RELATIVE_ERROR`).

    The polynomial is evaluated in Estrin's form: independent pairs first, so its latency is about
    four multiply-adds, not twelve.
    """
    s = t * t
    s2 = s * s
    s4 = s2 * s2
    s8 = s4 * s4
    p01, p23, p45 = _A0 + _A1 * s, _A2 + _A3 * s, _A4 + _A5 * s
    p67, p89, p1011 = _A6 + _A7 * s, _A8 + _A9 * s, _A10 + _A11 * s
    low = (p01 + p23 * s2) + (p45 + p67 * s2) * s4
    high = p89 + p1011 * s2
    return t * (low + high * s8)


@njit(inline="always")
def drift_angle(vy: float, vx: float) -> float:
    """``arctan(vy / vx)`` in ``[-pi/2, pi/2]``, eq. (20)'s ``alpha`` (``+-pi/2`` at ``vx = 0``, 0 at rest).

    Equal to :func:`pectoral_gym.model.dynamics._undamped_accel`'s ``atan2`` form within
    :data:`ATAN_RELATIVE_ERROR` (relative), with one division and a polynomial.
    """
    a, b = abs(vx), abs(vy)
    if b <= a:
        angle = fast_atan_unit(b / a) if a > 0.0 else 0.0
    else:
        angle = 0.5 * math.pi - fast_atan_unit(a / b)
    # atan2(vy, vx) for vx >= 0 and -atan2(vy, -vx) for vx < 0: the sign of vy / vx (vx = -0.0 counts as >= 0)
    return angle if (vy >= 0.0) == (vx >= 0.0) else -angle


@njit(inline="always")
def _asin_small(x: float) -> float:
    """``asin(x)`` for ``|x| <= 1/2`` (Estrin's form)."""
    s = x * x
    s2 = s * s
    s4 = s2 * s2
    low = (_S0 + _S1 * s) + (_S2 + _S3 * s) * s2 + ((_S4 + _S5 * s) + (_S6 + _S7 * s) * s2) * s4
    return x * (low + _S8 * s4 * s4)


@njit(inline="always")
def fast_asin(x: float) -> float:
    """``asin(x)`` for ``|x| <= 1`` (relative error below :data:`ASIN_RELATIVE_ERROR`).

    Beyond ``|x| = 1/2``: ``asin(x) = pi/2 - 2 asin(sqrt((1 - x) / 2))`` for ``x > 0`` (odd in ``x``).
    """
    a = abs(x)
    if a <= 0.5:
        return _asin_small(x)
    angle = 0.5 * math.pi - 2.0 * _asin_small(math.sqrt(0.5 * (1.0 - a)))
    return angle if x > 0.0 else -angle


@njit(inline="always")
def fast_oscillating_square_mean(mean: float, amplitude: float) -> float:
    """:func:`pectoral_gym.model.dynamics.oscillating_square_mean` with :func:`fast_asin` for libm's ``asin``."""
    u = mean / amplitude if amplitude > 0.0 else 0.0
    if amplitude <= 0.0 or abs(u) >= 1.0:  # the branches without an arcsin: the exact function's own
        return oscillating_square_mean(mean, amplitude)
    a2 = amplitude * amplitude
    return a2 * (2.0 * fast_asin(u) / math.pi * (u * u + 0.5) + 3.0 / math.pi * u * math.sqrt(1.0 - u * u))


@njit
def rotate(c0, s0, delta):
    """``cos, sin`` of ``psi0 + delta`` from those of ``psi0``.

    RK4 stages move the heading by at most ``h |omega|``, a small angle: a
    short series (error below 1e-12 for ``|delta| <= 0.1``) replaces three of
    the four ``sin/cos`` pairs per step.
    """
    if abs(delta) > 0.1:
        cd, sd = math.cos(delta), math.sin(delta)
    else:
        d2 = delta * delta
        cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0 - d2 / 720.0))
        sd = delta * (1.0 - d2 * (1.0 / 6.0 - d2 / 120.0))
    return c0 * cd - s0 * sd, s0 * cd + c0 * sd


@njit(inline="always")
def _damping_and_slope(omega: float, amplitude: float, inverse_amplitude: float):
    """The oscillation-averaged yaw damping ``D(omega)`` (:func:`fast_oscillating_square_mean`) and its slope.

    ``dD/domega = 2 mean|omega + A sin theta|``: ``(4 A / pi)(u arcsin u + sqrt(1 - u^2))`` for ``|u| < 1``
    (``u = omega / A``, by ``inverse_amplitude = 1 / A``), ``2 |omega|`` otherwise; it shares the ``arcsin``
    and the root with ``D``.
    """
    if amplitude > 0.0:
        u = omega * inverse_amplitude
        if abs(u) < 1.0:
            a = fast_asin(u)
            root = math.sqrt(1.0 - u * u)
            damping = amplitude * amplitude * (2.0 * a / math.pi * (u * u + 0.5) + 3.0 / math.pi * u * root)
            return damping, 4.0 / math.pi * amplitude * (u * a + root)
        return math.copysign(amplitude * amplitude * (u * u + 0.5), u), 2.0 * abs(omega)
    return omega * abs(omega), 2.0 * abs(omega)


@njit(inline="always")
def _scaled_accel(vx, vy, omega, fx, fy, moment, b: BodyCoefficients, inverse_m1, inverse_m2, munk, amplitude,
                  inverse_amplitude):
    """Eqs. (19)-(20) with :func:`drift_angle` and the fast ``arcsin`` (reciprocals of the constants given); and ``dD``.

    ``fx, fy``: the fin force [N]; ``moment = tau / J3`` [1/s^2]; ``munk = (m1 - m2) / J3`` [1/m^2].
    Returns ``(dvx, dvy, domega, dD/domega)`` (:func:`_damping_and_slope`).
    """
    speed = math.sqrt(vx * vx + vy * vy)
    alpha = drift_angle(vy, vx)
    dvx = (b.m2 * vy * omega - b.c1 * vx * speed + b.c2 * vy * speed * alpha + fx) * inverse_m1
    dvy = (-b.m1 * vx * omega - b.c1 * vy * speed - b.c2 * vx * speed * alpha + fy) * inverse_m2
    damping, slope = _damping_and_slope(omega, amplitude, inverse_amplitude)
    return dvx, dvy, munk * vx * vy - b.c4 * damping + moment, slope


# sin x = x S(x^2) and cos x = C(x^2) by their Taylor series through x^15 and x^16: for |x| <= pi/2 the
# remainders (alternating series of decreasing terms) are below |x|^17 / 17! = 6.1e-12 and |x|^18 / 18! = 5.3e-13.
_SIN = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(8))
_COS = tuple((-1.0) ** k / math.factorial(2 * k) for k in range(9))
#: Bound of the absolute error of :func:`sin_cos_half_turn` and :func:`sin_cos_of_angle` (``|x|^17 / 17!`` at pi/2).
SIN_COS_ERROR = 7e-12


@njit(inline="always")
def sin_cos_half_turn(x: float):
    """``(sin x, cos x)`` for ``|x| <= pi/2`` by Taylor polynomials (error below :data:`SIN_COS_ERROR`); libm beyond."""
    if abs(x) > 0.5 * math.pi:
        return math.sin(x), math.cos(x)
    s = x * x
    s2 = s * s
    s4 = s2 * s2
    sin_low = (_SIN[0] + _SIN[1] * s) + (_SIN[2] + _SIN[3] * s) * s2
    sin_high = (_SIN[4] + _SIN[5] * s) + (_SIN[6] + _SIN[7] * s) * s2
    cos_low = (_COS[0] + _COS[1] * s) + (_COS[2] + _COS[3] * s) * s2
    cos_high = (_COS[4] + _COS[5] * s) + (_COS[6] + _COS[7] * s) * s2 + _COS[8] * s4
    return x * (sin_low + sin_high * s4), cos_low + cos_high * s4


@njit(inline="always")
def sin_cos_of_angle(angle: float):
    """``(sin, cos)`` of a fin angle in ``[0, pi]`` by :func:`sin_cos_half_turn` of ``angle - pi/2``; libm beyond."""
    s, c = sin_cos_half_turn(angle - 0.5 * math.pi)
    return c, -s


# J1(x) = x sum_k (-1)^k (x/2)^(2k) / (2 k! (k+1)!), k <= 8: for |x| <= pi/2 the first term left out,
# |x/2|^19 / (9! 10!), is below 7.7e-15 (the series alternates with decreasing terms there).
_J1 = tuple((-1.0) ** k / (2.0 * math.factorial(k) * math.factorial(k + 1) * 4.0 ** k) for k in range(9))
#: Bound of the absolute error of :func:`short_bessel_j1` (``|x/2|^19 / (9! 10!)`` at pi/2, and rounding).
BESSEL_J1_ERROR = 1e-14


@njit(inline="always")
def short_bessel_j1(x: float) -> float:
    """``J1(x)`` for ``|x| <= pi/2`` only: nine terms of its series, coefficients precomputed (Estrin's form).

    Fin amplitudes and half-strokes stay within ``pi/2`` (the stroke lies in ``[0, pi]``); callers use
    :func:`pectoral_gym.model.averaging.bessel_j1` (18 terms, a division each) beyond it.
    """
    s = x * x
    s2 = s * s
    s4 = s2 * s2
    low = (_J1[0] + _J1[1] * s) + (_J1[2] + _J1[3] * s) * s2
    high = (_J1[4] + _J1[5] * s) + (_J1[6] + _J1[7] * s) * s2
    return x * (low + (high + _J1[8] * s4) * s4)



# The ETD-RK4 weights (Cox and Matthews 2002) f1, f2, f3 of z = c h: (-4 - z + e^z (4 - 3z + z^2)) / z^3,
# (2 + z + e^z (z - 2)) / z^3 and (-4 - 3z - z^2 + e^z (4 - z)) / z^3. Near z = 0 the closed forms cancel
# (their rounding grows as 1e-15 / |z|^3), so below EXPONENTIAL_SERIES_LIMIT their Taylor series through z^9 are
# used (coefficients from the series of e^z; the first term left out is below 1e-15 there).
EXPONENTIAL_SERIES_LIMIT = 0.2
_F1 = (1 / 6, 1 / 6, 3 / 40, 1 / 45, 5 / 1008, 1 / 1120, 7 / 51840, 1 / 56700, 1 / 492800, 1 / 4790016)
_F2 = (1 / 6, 1 / 12, 1 / 40, 1 / 180, 1 / 1008, 1 / 6720, 1 / 51840, 1 / 453600, 1 / 4435200, 1 / 47900160)
_F3 = (1 / 6, 0.0, -1 / 120, -1 / 360, -1 / 1680, -1 / 10080, -1 / 72576, -1 / 604800, -1 / 5702400, -1 / 59875200)


@njit(inline="always")
def _series(c, z):
    """``sum_k c[k] z^k`` over the ten coefficients ``c`` (Estrin's form)."""
    z2 = z * z
    z4 = z2 * z2
    z8 = z4 * z4
    low = (c[0] + c[1] * z) + (c[2] + c[3] * z) * z2 + ((c[4] + c[5] * z) + (c[6] + c[7] * z) * z2) * z4
    return low + (c[8] + c[9] * z) * z8


@njit(inline="always")
def exponential_weights(z: float):
    """ETD-RK4 weights of a linear rate ``c`` over a step ``h``, ``z = c h <= 0``.

    Returns ``(e^(z/2), (e^(z/2) - 1) / z, f1, f2, f3)`` (the second is ``1/2`` at ``z = 0``); at ``z = 0``
    the scheme is the classical RK4 (``f1 = f2 = f3 = 1/6``).
    """
    half_minus_one = math.expm1(0.5 * z)
    half = 1.0 + half_minus_one
    if z > -EXPONENTIAL_SERIES_LIMIT:
        ratio = half_minus_one / z if z < 0.0 else 0.5
        return half, ratio, _series(_F1, z), _series(_F2, z), _series(_F3, z)
    full = half * half
    inverse = 1.0 / z
    inverse3 = inverse * inverse * inverse
    return (half, half_minus_one * inverse, (-4.0 - z + full * (4.0 - 3.0 * z + z * z)) * inverse3,
            (2.0 + z + full * (z - 2.0)) * inverse3, (-4.0 - 3.0 * z - z * z + full * (4.0 - z)) * inverse3)


@njit(inline="always")
def _turned(c0, s0, delta):
    """:func:`rotate`, with :func:`sin_cos_half_turn`'s polynomials for ``0.1 < |delta| <= pi/2`` (libm beyond).

    The fast step's substeps are long enough for a turning fish's stages to pass ``rotate``'s short series.
    """
    if abs(delta) <= 0.1:
        return rotate(c0, s0, delta)
    sd, cd = sin_cos_half_turn(delta)
    return c0 * cd - s0 * sd, s0 * cd + c0 * sd


@njit(inline="always")
def exponential_substep(state, integral, i, t_left, f: Forcing, b: BodyCoefficients, rates: RateConstants, osc,
                        driven_omega, driven_speed, c0, s0, dt_max, accurate):
    """One substep of the fast step: ETD-RK4 in the yaw rate, classical RK4 in the rest; returns ``c, s, h``.

    The yaw damping's linearisation at the substep's start, ``-lambda omega`` with ``lambda = c4 dD/domega``
    (:func:`fast_damping_and_slope`), is integrated exactly (Cox and Matthews' exponential time differencing
    RK4, :func:`exponential_weights`); what is left of eq. (20)'s ``f3`` beyond it, ``f3 + lambda omega``,
    and ``vx, vy``, the pose and the running integrals are stepped as by RK4 (the same stages; at
    ``lambda = 0`` this is RK4). Equilibria stay equilibria (a state with zero accelerations does not move).

    The step ``h`` divides ``t_left`` into equal substeps of at most ``dt_max`` with ``h * rate <= accurate``,
    where the rate is :func:`pectoral_gym.model.dynamics.rate_bound`'s with the yaw damping's part replaced
    by what the linearisation leaves out: ``2 c4`` times the yaw rate's distance to its Newton estimate of
    equilibrium ``|f3| / lambda`` (at most ``|omega| + driven_omega``; ``dD/domega`` changes by at most twice
    the change of ``omega``). ``driven_omega, driven_speed``: as for ``stepping._stable_step``.
    """
    x0, y0, p0 = state[i, 0], state[i, 1], state[i, 2]
    u0, v0, w0 = state[i, 3], state[i, 4], state[i, 5]
    # the constants' reciprocals, off the stages' chain of dependent operations
    inverse_m1, inverse_m2, inverse_j3 = 1.0 / b.m1, 1.0 / b.m2, 1.0 / b.J3
    munk, moment = (b.m1 - b.m2) * inverse_j3, f.tau * inverse_j3
    inverse_amplitude = 1.0 / osc if osc > 0.0 else 0.0
    k1u, k1v, k1w, slope = _scaled_accel(u0, v0, w0, f.fx, f.fy, moment, b, inverse_m1, inverse_m2, munk, osc,
                                         inverse_amplitude)
    speed0 = math.sqrt(u0 * u0 + v0 * v0)
    lam = b.c4 * slope
    omega_reach = abs(w0) + driven_omega
    if abs(k1w) < lam * omega_reach:
        omega_reach = abs(k1w) / lam
    w_abs = max(abs(w0), driven_omega)
    speed = max(speed0, driven_speed)
    rate = max(rates.yaw * omega_reach, rates.drag * speed + rates.coriolis * w_abs) + rates.munk * speed
    h_ok = accurate / rate if rate * dt_max > accurate else dt_max
    h = t_left / max(1, int(math.ceil(t_left / h_ok - 1e-9)))
    half, ratio, f1, f2, f3 = exponential_weights(-lam * h)
    n1 = k1w + lam * w0  # the rate's part beyond its linearisation
    # stage 2: (u0, v0) + h/2 k1; the yaw rate by the exponential
    u2, v2 = u0 + 0.5 * h * k1u, v0 + 0.5 * h * k1v
    w2 = half * w0 + h * ratio * n1
    k1p = w0
    c, s = _turned(c0, s0, 0.5 * h * k1p)
    k2x, k2y = u2 * c - v2 * s, u2 * s + v2 * c
    k2u, k2v, k2w, _ = _scaled_accel(u2, v2, w2, f.fx, f.fy, moment, b, inverse_m1, inverse_m2, munk, osc,
                                       inverse_amplitude)
    n2 = k2w + lam * w2
    # stage 3
    u3, v3 = u0 + 0.5 * h * k2u, v0 + 0.5 * h * k2v
    w3 = half * w0 + h * ratio * n2
    c, s = _turned(c0, s0, 0.5 * h * w2)
    k3x, k3y = u3 * c - v3 * s, u3 * s + v3 * c
    k3u, k3v, k3w, _ = _scaled_accel(u3, v3, w3, f.fx, f.fy, moment, b, inverse_m1, inverse_m2, munk, osc,
                                       inverse_amplitude)
    n3 = k3w + lam * w3
    # stage 4: Cox and Matthews' c = e^(z/2) a + h ratio (2 N(b) - N(u)); RK4's u0 + h k3 in the rest
    u4, v4 = u0 + h * k3u, v0 + h * k3v
    w4 = half * w2 + h * ratio * (2.0 * n3 - n1)
    c, s = _turned(c0, s0, h * w3)
    k4x, k4y = u4 * c - v4 * s, u4 * s + v4 * c
    k4u, k4v, k4w, _ = _scaled_accel(u4, v4, w4, f.fx, f.fy, moment, b, inverse_m1, inverse_m2, munk, osc,
                                       inverse_amplitude)
    n4 = k4w + lam * w4
    h6 = h / 6.0
    k1x, k1y = u0 * c0 - v0 * s0, u0 * s0 + v0 * c0
    state[i, 0] = x0 + h6 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
    state[i, 1] = y0 + h6 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y)
    turn = h6 * (w0 + 2.0 * w2 + 2.0 * w3 + w4)  # RK4's quadrature of the stages' rates, as the position's
    state[i, 2] = p0 + turn
    state[i, 3] = u0 + h6 * (k1u + 2.0 * k2u + 2.0 * k3u + k4u)
    state[i, 4] = v0 + h6 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
    state[i, 5] = half * half * w0 + h * (f1 * n1 + 2.0 * f2 * (n2 + n3) + f3 * n4)
    integral[i, 0] += h6 * (u0 + 2.0 * u2 + 2.0 * u3 + u4)
    integral[i, 1] += h6 * (v0 + 2.0 * v2 + 2.0 * v3 + v4)
    integral[i, 2] += turn
    c, s = _turned(c0, s0, turn)
    return c, s, h
