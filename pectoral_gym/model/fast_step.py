"""The averaged model's fast step: bounded-range function approximations and a carried heading (compiled).

The averaged model's ``fast_step`` option (:class:`pectoral_gym.model.models.AveragedModel`) integrates
the same equations (19)-(20) with the oscillation-averaged yaw damping (``docs/model.md`` 3.6) as the
default step, with three changes that trade exact libm calls and small substeps for speed:

* the drift angle ``alpha = arctan(v_y / v_x)`` of eq. (20) by :func:`drift_angle`, an odd polynomial
  on ``[0, 1]`` after the octant reduction (relative error below :data:`ATAN_RELATIVE_ERROR`), instead of
  libm's ``atan2``;
* the ``arcsin`` of :func:`pectoral_gym.model.dynamics.oscillating_square_mean` by :func:`fast_asin`, an
  odd polynomial on ``[0, 1/2]`` and the half-angle identity beyond (relative error below
  :data:`ASIN_RELATIVE_ERROR`), instead of libm's ``asin``;
* the heading's ``cos, sin`` carried from substep to substep within a segment by the small-angle
  rotation the RK4 stages use already (:func:`pectoral_gym.model.stepping._rotate`), instead of
  libm's ``cos, sin`` at every substep; a segment starts from libm's values of its heading;
* substeps sized to ``h * rate <= FAST_ACCURATE_STEP`` (:func:`pectoral_gym.model.stepping._stable_step`)
  instead of :data:`pectoral_gym.model.stepping.ACCURATE_STEP`, still inside RK4's stability limit (2.78).

The polynomials' coefficients are least-squares fits of the relative error on Chebyshev nodes
(docs/notes/2026-12-07-fast-averaged-step.md); their error bounds are asserted against libm over their
whole ranges in ``tests/test_fast_step.py``.
"""

from __future__ import annotations

import math

from pectoral_gym.model.dynamics import Forcing, oscillating_square_mean
from pectoral_gym.model.jit import njit
from pectoral_gym.model.params import BodyCoefficients

__all__ = ["ASIN_RELATIVE_ERROR", "ATAN_RELATIVE_ERROR", "BESSEL_J1_ERROR", "FAST_ACCURATE_STEP", "SIN_COS_ERROR",
           "drift_angle", "fast_asin", "fast_atan_unit", "fast_body_accel", "fast_oscillating_square_mean",
           "short_bessel_j1", "sin_cos_half_turn", "sin_cos_of_angle"]

#: The fast step's ``h * rate`` bound (the default step's is ``stepping.ACCURATE_STEP``, 1.5); RK4's
#: stability limit on the negative real axis is 2.78.
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


@njit(inline="always")
def fast_body_accel(vx, vy, omega, f: Forcing, b: BodyCoefficients, oscillation):
    """:func:`~pectoral_gym.model.dynamics.body_accel`, with :func:`drift_angle` and the fast ``arcsin``."""
    speed = math.sqrt(vx * vx + vy * vy)
    alpha = drift_angle(vy, vx)
    dvx = (b.m2 * vy * omega - b.c1 * vx * speed + b.c2 * vy * speed * alpha + f.fx) / b.m1  # eqs. (19)-(20), f1
    dvy = (-b.m1 * vx * omega - b.c1 * vy * speed - b.c2 * vx * speed * alpha + f.fy) / b.m2  # f2 (erratum 3)
    if oscillation > 0.0:
        damping = fast_oscillating_square_mean(omega, oscillation)  # docs/model.md 3.6
    else:
        damping = omega * abs(omega)
    return dvx, dvy, (b.m1 - b.m2) / b.J3 * vx * vy - b.c4 * damping + f.tau / b.J3  # f3



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

