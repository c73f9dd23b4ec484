"""Blade-element fin forces and rigid-body dynamics (eqs. 1-20).

Scalar functions compiled with numba so that the integrators in
:mod:`pectoral_gym.integrators` call them without Python overhead. They are
plain functions of floats and can be called from Python too (tests do).

Conventions (``docs/model.md``): body frame x forward, y to the left, z up;
``omega > 0`` is a left (counter-clockwise) turn. The right fin pivots at
``y = -C_p``, the left fin at ``y = +C_p``. Fin angle ``g`` is measured from the
body x-axis; ``g`` increasing sweeps the fin backward (power stroke).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = [
    "stroke_kinematics",
    "fin_force_right",
    "body_rhs",
    "body_accel",
    "fin_angle_eq21",
]

_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}


@nb.njit(**_JIT)
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


@nb.njit(**_JIT)
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
    sg = math.sin(g)
    cg = math.cos(g)
    fn = -drag_constant * gd * abs(gd)  # eq. (13) along n
    # n = (-sin g, -cos g), m = (cos g, -sin g) in body axes (eqs. 7-8);
    # a(S_p/2) = S_p/2 (g'' n - g'^2 m) (eq. 10).
    fx = -fn * sg + inertia_constant * (gdd * sg + gd * gd * cg)  # eq. (16)
    fy = -fn * cg + inertia_constant * (gdd * cg - gd * gd * sg)  # eq. (17)
    return fx, fy


@nb.njit(**_JIT)
def body_accel(vx, vy, omega, fx, fy, tau, m1, m2, j3, c1, c2, c4):
    """Body-frame accelerations of eq. (19) with ``f_1, f_2, f_3`` of eq. (20), scalar coefficients.

    ``alpha = arctan(v_y / v_x)`` is evaluated as the paper writes it (a value in
    [-pi/2, pi/2], also when swimming backward) without dividing by zero.
    """
    speed = math.sqrt(vx * vx + vy * vy)
    if vx >= 0.0:
        alpha = math.atan2(vy, vx)
    else:
        alpha = -math.atan2(vy, -vx)  # arctan(vy/vx) for vx < 0
    dvx = (m2 * vy * omega - c1 * vx * speed + c2 * vy * speed * alpha + fx) / m1  # eqs. (19)-(20), f1
    dvy = (-m1 * vx * omega - c1 * vy * speed - c2 * vx * speed * alpha + fy) / m2  # f2 (erratum 3)
    dom = (m1 - m2) / j3 * vx * vy - c4 * omega * abs(omega) + tau / j3  # f3
    return dvx, dvy, dom


@nb.njit(**_JIT)
def body_rhs(vx: float, vy: float, omega: float, fx: float, fy: float, tau: float, coef):
    """Body-frame accelerations of eq. (19) with ``f_1, f_2, f_3`` of eq. (20).

    Args:
        vx, vy, omega: Surge [m/s], sway [m/s], yaw rate [rad/s].
        fx, fy, tau: Total fin force [N] and moment [N m] on the body.
        coef: Packed coefficients, see ``params.COEF_NAMES``.

    Returns:
        ``(dvx, dvy, domega)``.
    """
    return body_accel(vx, vy, omega, fx, fy, tau, coef[0], coef[1], coef[2], coef[3], coef[4], coef[5])


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
