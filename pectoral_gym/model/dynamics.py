"""Blade-element fin forces and rigid-body dynamics (eqs. 1-20).

Scalar functions compiled with numba so that the model kernels in
:mod:`pectoral_gym.model.strokes` and :mod:`pectoral_gym.model.stepping` call them without Python overhead. They are
plain functions of floats and can be called from Python too (tests do).

Conventions (``docs/model.md``): body frame x forward, y to the left, z up;
``omega > 0`` is a left (counter-clockwise) turn. The right fin pivots at
``y = -C_p``, the left fin at ``y = +C_p``. Fin angle ``g`` is measured from the
body x-axis; ``g`` increasing sweeps the fin backward (power stroke).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from pectoral_gym.model.jit import njit
from pectoral_gym.model.params import Coef

__all__ = [
    "Forcing",
    "stroke_kinematics",
    "fin_force_right",
    "fin_force_at",
    "body_rhs",
    "body_accel",
    "fin_angle_eq21",
    "RateConstants",
    "linearised_rate",
    "rate_bound",
    "rate_constants",
    "oscillating_square_mean",
]


class RateConstants(NamedTuple):
    """The body-coefficient factors of :func:`linearised_rate` (``r = max(m1/m2, m2/m1)``)."""

    yaw: float  # 1/rad, 2 c4: yaw-damping rate [1/s] per unit yaw rate [rad/s]
    drag: float  # 1/m, (max(2 c1, c1 + c2) + pi c2) / min(m1, m2): drag and lift rate per unit speed
    coriolis: float  # -, r: Coriolis rate per unit yaw rate
    munk: float  # 1/m, sqrt(r |m1 - m2| / J3): Munk-coupling rate per unit speed


class Forcing(NamedTuple):
    """Total fin force and moment on the body, body frame (eq. 18)."""

    fx: float  # N, surge force f_hx
    fy: float  # N, sway force f_hy
    tau: float  # N m, yaw moment


@njit
def stroke_kinematics(elapsed: float, duration: float, angle_from: float, angle_to: float):
    """Fin angle and its exact derivatives within one half-stroke.

    Each half of eq. (21) is a half-cosine between two turning points:
    ``g = mid - half cos(pi s / d)`` with ``mid, half`` the centre and signed
    half-width of the stroke, ``s`` the time into it and ``d`` its duration.
    With constant parameters this is exactly eq. (21); when parameters change
    it joins the old turning point to the new one with ``g`` and ``g'``
    continuous (``docs/model.md``, "Changing fin parameters").

    Returns:
        ``(g, g', g'')`` in rad, rad/s, rad/s^2.
    """
    mid = 0.5 * (angle_from + angle_to)
    half = 0.5 * (angle_to - angle_from)
    rate = math.pi / duration
    phase = rate * elapsed
    c = math.cos(phase)
    s = math.sin(phase)
    return mid - half * c, half * rate * s, half * rate * rate * c


@njit
def fin_force_right(g: float, gd: float, gdd: float, drag_constant: float, inertia_constant: float):
    """Force of the right fin on the body, body frame (eqs. 9-17).

    The blade velocity (9) is ``s g' n``, normal to the fin, so the angle of
    attack (12) is 90 deg and ``C_n = lambda``; with the sign fix of erratum 4
    (drag opposes velocity) eqs. (11) and (13) integrate to
    ``F_n = -k g'|g'|`` with ``k = lambda rho D_p S_p^3 / 6``. Eq. (15) gives the
    joint force ``F_A0 = F_n n - m_p a(S_p/2)`` with the acceleration (10), and
    (16)-(17) project it on the body axes using (7)-(8).

    Args:
        g, gd, gdd: Fin angle [rad] and its first two derivatives.
        drag_constant: ``k`` [N s^2] (``FishParams.fin_drag_constant``).
        inertia_constant: ``m_p S_p / 2`` [kg m].

    Returns:
        ``(f_hx, f_hy)`` [N] on the body from the right fin.
    """
    return fin_force_at(math.sin(g), math.cos(g), gd, gdd, drag_constant, inertia_constant)


@njit(inline="always")
def fin_force_at(sg: float, cg: float, gd: float, gdd: float, drag_constant: float, inertia_constant: float):
    """:func:`fin_force_right` from ``sin g, cos g`` (for callers that have them without calling ``sin/cos``)."""
    fn = -drag_constant * gd * abs(gd)  # eq. (13) along n
    # n = (-sin g, -cos g), m = (cos g, -sin g) in body axes (eqs. 7-8);
    # a(S_p/2) = S_p/2 (g'' n - g'^2 m) (eq. 10).
    fx = -fn * sg + inertia_constant * (gdd * sg + gd * gd * cg)  # eq. (16)
    fy = -fn * cg + inertia_constant * (gdd * cg - gd * gd * sg)  # eq. (17)
    return fx, fy


@njit
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


@njit
def _undamped_accel(vx, vy, omega, fx, fy, tau, m1, m2, j3, c1, c2):
    """Eq. (19) with ``f_1, f_2`` of eq. (20), and the Munk and fin terms of ``f_3`` (without its yaw damping)."""
    speed = math.sqrt(vx * vx + vy * vy)
    if vx >= 0.0:
        alpha = math.atan2(vy, vx)
    else:
        alpha = -math.atan2(vy, -vx)  # arctan(vy/vx) for vx < 0
    dvx = (m2 * vy * omega - c1 * vx * speed + c2 * vy * speed * alpha + fx) / m1  # eqs. (19)-(20), f1
    dvy = (-m1 * vx * omega - c1 * vy * speed - c2 * vx * speed * alpha + fy) / m2  # f2 (erratum 3)
    return dvx, dvy, (m1 - m2) / j3 * vx * vy, tau / j3  # f3 = munk - c4 damping + moment


@njit
def body_accel(vx, vy, omega, fx, fy, tau, m1, m2, j3, c1, c2, c4, oscillation=0.0):
    """Body-frame accelerations of eq. (19) with ``f_1, f_2, f_3`` of eq. (20), scalar coefficients.

    ``alpha = arctan(v_y / v_x)`` is evaluated as the paper writes it (a value in
    [-pi/2, pi/2], also when swimming backward) without dividing by zero.

    ``oscillation`` [rad/s] > 0 gives the averaged model's oscillation-averaged
    yaw damping (``docs/model.md`` 3.6, beyond the paper): ``c4 omega|omega|``
    is replaced by its mean over an in-beat yaw oscillation of that amplitude,
    ``c4 oscillating_square_mean(omega, oscillation)``. The default 0 is eq. (20).
    """
    dvx, dvy, munk, moment = _undamped_accel(vx, vy, omega, fx, fy, tau, m1, m2, j3, c1, c2)
    if oscillation > 0.0:
        damping = oscillating_square_mean(omega, oscillation)  # docs/model.md 3.6
    else:
        damping = omega * abs(omega)
    return dvx, dvy, munk - c4 * damping + moment  # f3


@njit
def body_rhs(vx: float, vy: float, omega: float, fx: float, fy: float, tau: float, coef):
    """Body-frame accelerations of eq. (19) with ``f_1, f_2, f_3`` of eq. (20).

    Args:
        vx, vy, omega: Surge [m/s], sway [m/s], yaw rate [rad/s].
        fx, fy, tau: Total fin force [N] and moment [N m] on the body.
        coef: Packed coefficients, see ``params.COEF_NAMES``.

    Returns:
        ``(dvx, dvy, domega)``.
    """
    return body_accel(vx, vy, omega, fx, fy, tau, coef[Coef.M1], coef[Coef.M2], coef[Coef.J3],
                      coef[Coef.C1], coef[Coef.C2], coef[Coef.C4])


@njit
def linearised_rate(speed, omega, oscillation, m1, m2, j3, c1, c2, c4):
    """Upper bound [1/s] on the eigenvalue moduli of the Jacobian of eqs. (19)-(20) in ``(vx, vy, omega)``.

    The step-size rule of every explicit integrator of the body dynamics: the
    averaged model's RK4 (:mod:`pectoral_gym.model.stepping`) and the scaling NMPC's
    (``pectoral_gym.scaling.identification.nmpc.auto_substeps``). RK4 is stable for ``h * rate <= 2.78``.

    Derivation, at speed ``V = |v|``, drift angle ``alpha`` (``|alpha| <= pi/2``),
    yaw rate ``w``, with ``u = J v = (vy, -vx)`` (``|u| = V``, ``u . v = 0``) and
    ``r = max(m1/m2, m2/m1)``. The Jacobian has three parts:

    * the velocity block ``-M^-1 (S + L) + C`` with ``M = diag(m1, m2)``:
      the drag ``c1 v V`` of f1, f2 gives ``S = c1 (V I + v v'/V)`` (eigenvalues
      ``c1 V`` across, ``2 c1 V`` along ``v``); the lift ``c2 alpha V u`` gives a
      symmetric ``(c2 / V) u u'`` (``c2 V`` across, since ``d alpha = -u . dv / V^2``)
      plus ``-c2 alpha (V J + u v'/V)``, of norm at most ``2 c2 |alpha| V <= pi c2 V``.
      ``S`` plus the symmetric lift has eigenvalues ``2 c1 V`` and ``(c1 + c2) V``, so with
      ``M^-1`` its norm is at most ``max(2 c1, c1 + c2) V / min(m1, m2)``; the Coriolis
      terms ``C = w [[0, m2/m1], [-m1/m2, 0]]`` have norm ``r |w|``.
    * the yaw damping ``-c4 w|w|`` of f3: ``2 c4 |w|``; with the
      oscillation-averaged damping (amplitude ``A``, :func:`body_accel`) the slope
      ``2 c4 mean|w + A sin|`` is at most ``2 c4 (|w| + 2 A / pi)``.
    * the couplings ``d f_v / d w = (m2 vy / m1, -m1 vx / m2)`` (norm ``<= r V``) and
      the Munk moment ``d f3 / d v = (m1 - m2) (vy, vx) / J3`` (norm ``|m1 - m2| V / J3``):
      after rescaling ``w`` (a similarity, eigenvalues unchanged) the pair has
      norm ``V sqrt(r |m1 - m2| / J3)``.

    The block-diagonal part (velocity block, yaw entry) has the larger of the
    two norms, the coupling adds its own: the spectral radius is at most
    ``max(yaw, velocity) + coupling``. For Table 1 the lift adds
    ``pi c2 / (2 c1) = 33 %`` to the drag bound, the Munk coupling is ``14 V``
    [1/s], and in a turn the yaw damping (``2 c4 = 38`` per rad/s) sets the step.

    Args:
        speed: ``V`` [m/s]; omega: ``|w|`` [rad/s]; oscillation: ``A`` [rad/s] (0: eq. 20).
        m1, m2, j3, c1, c2, c4: Body coefficients (eq. 20).
    """
    return rate_bound(speed, omega, oscillation, rate_constants(m1, m2, j3, c1, c2, c4))


@njit
def rate_constants(m1, m2, j3, c1, c2, c4) -> RateConstants:
    """The factors of :func:`linearised_rate` that depend on the body coefficients only (eq. 20)."""
    ratio = max(m1 / m2, m2 / m1)
    return RateConstants(2.0 * c4, (max(2.0 * c1, c1 + c2) + math.pi * c2) / min(m1, m2), ratio,
                         math.sqrt(ratio * abs(m1 - m2) / j3))


@njit
def rate_bound(speed, omega, oscillation, k: RateConstants):
    """:func:`linearised_rate` from its precomputed :class:`RateConstants` (the integrators' inner loop)."""
    omega = abs(omega)
    yaw = k.yaw * (omega + 2.0 / math.pi * oscillation)
    velocity = k.drag * speed + k.coriolis * omega
    return max(yaw, velocity) + k.munk * speed


def fin_angle_eq21(t: np.ndarray, bias: float, amplitude: float, period: float, ratio: float):
    """Fin angle of eq. (21) and its exact derivatives at times ``t`` (numpy).

    The reference form of the paper, used by analysis and tests; the
    integrators use :func:`stroke_kinematics`, which equals it for constant
    parameters.

    Returns:
        ``(g, g', g'')`` arrays shaped like ``t``.
    """
    t = np.mod(np.asarray(t, dtype=np.float64), period)
    t_power = period / (ratio + 1.0)
    w1 = math.pi * (ratio + 1.0) / period  # power-stroke rate, eq. (21) first line
    w2 = math.pi * (ratio + 1.0) / (ratio * period)  # recovery rate, second line
    power = t <= t_power
    p1 = w1 * t
    p2 = w2 * (t - t_power)
    g = np.where(power, bias - amplitude * np.cos(p1), bias + amplitude * np.cos(p2))
    gd = np.where(power, amplitude * w1 * np.sin(p1), -amplitude * w2 * np.sin(p2))
    gdd = np.where(power, amplitude * w1**2 * np.cos(p1), -amplitude * w2**2 * np.cos(p2))
    return g, gd, gdd
